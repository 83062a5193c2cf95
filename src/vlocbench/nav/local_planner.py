"""Local planner: picks the waypoint the controller steers towards.

The target stays between ``min_lookahead_s`` and ``max_lookahead_s`` of travel ahead of the closest
point of the path (0.9 s and 3.0 s, as in the paper); when it falls outside that band it is
recomputed from the closest point. Near the end of the path the target is the goal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vlocbench.config import require
from vlocbench.nav.path import Array, WaypointPath


@dataclass(frozen=True)
class LocalPlannerConfig:
    min_lookahead_s: float = 0.9
    max_lookahead_s: float = 3.0
    # floor of the lookahead band: at rest a time band is empty, and the car must still set off
    min_lookahead_m: float = 3.0
    # where in the band a recomputed target goes: 0 at its near edge, 1 at its far edge
    reselect_fraction: float = 1.0
    # the closest point is searched this far behind/ahead of the last one (a route may pass the same
    # street twice; a global search would jump between its visits)
    search_behind_m: float = 10.0
    search_ahead_m: float = 40.0

    def __post_init__(self) -> None:
        require(self.min_lookahead_s >= 0, "local_planner.min_lookahead_s", "must be >= 0")
        require(
            self.max_lookahead_s > self.min_lookahead_s,
            "local_planner.max_lookahead_s",
            "must be > min_lookahead_s",
        )
        require(self.min_lookahead_m > 0, "local_planner.min_lookahead_m", "must be > 0")
        require(
            0.0 <= self.reselect_fraction <= 1.0,
            "local_planner.reselect_fraction",
            "must be in [0, 1]",
        )
        require(self.search_behind_m >= 0, "local_planner.search_behind_m", "must be >= 0")
        require(self.search_ahead_m > 0, "local_planner.search_ahead_m", "must be > 0")


@dataclass(frozen=True)
class LocalTarget:
    """``index``/``xy``: the target waypoint; ``s_closest_m``: arc length of the closest point;
    ``remaining_m``: path left from there to the goal; ``offset_m``: distance from the path."""

    index: int
    xy: Array
    s_closest_m: float
    remaining_m: float
    offset_m: float


class LocalPlanner:
    def __init__(self, path: WaypointPath, config: LocalPlannerConfig | None = None) -> None:
        self.path = path
        self.config = config or LocalPlannerConfig()
        self.reset()

    def reset(self, s_m: float = 0.0) -> None:
        """Restart from arc length ``s_m`` (a start or a re-initialization)."""
        self._s_m = float(np.clip(s_m, 0.0, self.path.length_m))
        self._target: int | None = None

    def band_m(self, speed_mps: float) -> tuple[float, float]:
        """The lookahead band (near, far) in metres at ``speed_mps``."""
        c = self.config
        near = max(c.min_lookahead_s * speed_mps, c.min_lookahead_m)
        far = max(c.max_lookahead_s * speed_mps, near + float(np.max(np.diff(self.path.s_m))))
        return near, far

    def step(self, xy: Array, speed_mps: float) -> LocalTarget:
        """Target for a car believed to be at ``xy`` (2,) moving at ``speed_mps``."""
        c, path = self.config, self.path
        first, last = path.window(self._s_m, c.search_behind_m, c.search_ahead_m)
        proj = path.project(xy, first, last)
        self._s_m = proj.s_m
        near, far = self.band_m(abs(speed_mps))
        if self._s_m + near >= path.length_m:
            self._target = len(path) - 1
        elif self._target is None or not (near <= path.s_m[self._target] - self._s_m <= far):
            goal_s = self._s_m + near + c.reselect_fraction * (far - near)
            # the last waypoint not beyond goal_s, but never closer than the band's near edge
            idx = int(np.searchsorted(path.s_m, goal_s, side="right")) - 1
            self._target = max(idx, path.index_at(self._s_m + near))
        return LocalTarget(
            index=self._target,
            xy=path.xy[self._target],
            s_closest_m=self._s_m,
            remaining_m=path.length_m - self._s_m,
            offset_m=proj.distance_m,
        )
