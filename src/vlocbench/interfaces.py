"""Values that cross stage boundaries, defined once: the array aliases every stage annotates with,
and the vehicle command the controller (``nav``) gives and the simulated car (``sim``) takes, since
those two stages never import each other."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vlocbench.config import require

Array = NDArray[np.float64]
Image = NDArray[np.uint8]  # (H, W, 3) RGB unless a docstring says otherwise


@dataclass(frozen=True)
class Control:
    """CARLA-style command: throttle and brake in [0, 1], steer in [-1, 1] (positive = left)."""

    throttle: float = 0.0
    steer: float = 0.0
    brake: float = 0.0

    def __post_init__(self) -> None:
        for name, lo in (("throttle", 0.0), ("steer", -1.0), ("brake", 0.0)):
            v = getattr(self, name)
            require(
                np.isfinite(v) and lo <= v <= 1.0,
                f"control.{name}",
                f"must be in [{lo:g}, 1], got {v}",
            )
