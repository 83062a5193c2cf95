"""Route progress: the farthest waypoint the car has truly reached (where re-initialization goes)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vlocbench.config import require
from vlocbench.interfaces import Array
from vlocbench.nav.path import Projection, WaypointPath


@dataclass(frozen=True)
class ProgressConfig:
    max_route_distance_m: float = 4.0  # progress counts only this close to the route
    max_jump_m: float = 150.0  # and never jumps further ahead than this
    search_behind_m: float = 10.0
    goal_tolerance_m: float = 1.0

    def __post_init__(self) -> None:
        require(self.max_route_distance_m > 0, "progress.max_route_distance_m", "must be > 0")
        require(self.max_jump_m > 0, "progress.max_jump_m", "must be > 0")
        require(self.search_behind_m >= 0, "progress.search_behind_m", "must be >= 0")
        require(self.goal_tolerance_m > 0, "progress.goal_tolerance_m", "must be > 0")


class ProgressTracker:
    def __init__(self, path: WaypointPath, config: ProgressConfig | None = None) -> None:
        self.path = path
        self.config = config or ProgressConfig()
        self.farthest_s_m = 0.0

    def update(self, xy: Array) -> Projection:
        """Account for the car's true position (2,); returns its projection onto the route.

        Only the part of the route from ``search_behind_m`` behind the farthest point reached to
        ``max_jump_m`` ahead of it is searched.
        """
        c = self.config
        first, last = self.path.window(self.farthest_s_m, c.search_behind_m, c.max_jump_m)
        proj = self.path.project(xy, first, last)
        if (
            proj.distance_m <= c.max_route_distance_m
            and self.farthest_s_m < proj.s_m <= self.farthest_s_m + c.max_jump_m
        ):
            self.farthest_s_m = proj.s_m
        return proj

    @property
    def farthest_index(self) -> int:
        """The farthest waypoint reached (at or behind the farthest point)."""
        return int(np.searchsorted(self.path.s_m, self.farthest_s_m + 1e-6, side="right")) - 1

    @property
    def finished(self) -> bool:
        """The car has come within ``goal_tolerance_m`` of the end of the route."""
        return self.farthest_s_m >= self.path.length_m - self.config.goal_tolerance_m
