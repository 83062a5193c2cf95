"""Paths for the navigation tests."""

import numpy as np

from vlocbench.nav import WaypointPath


def straight(length_m: float) -> WaypointPath:
    """Along +x from the origin, a waypoint every 2 m."""
    x = np.arange(0.0, length_m + 1, 2.0)
    return WaypointPath(np.stack([x, np.zeros_like(x)], 1))
