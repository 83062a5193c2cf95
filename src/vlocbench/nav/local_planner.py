"""Local planner: picks the waypoint the controller steers towards.

``rule="paper"`` (the default) is the paper's planner: with d = the straight-line distance from
the car to a waypoint, near = ``min_lookahead_s`` and far = ``max_lookahead_s`` of travel at the
target speed (0.9 s and 3.0 s: 3.6 m and 12 m at 4 m/s), the target starts at the closest waypoint,
moves on while d < near, and is searched again (as the closest waypoint) once d > far. At 4 m/s and
2 m waypoints it sits about 4.6 m ahead. When the goal is within near, the goal is the target.

``rule="band"`` (vlocbench's own): the target is kept between near and far of arc length ahead of
the car's projection onto the path at its current speed (at least ``min_lookahead_m``), and when it
leaves that band it is recomputed at ``reselect_fraction`` of the band (the far edge by default,
about 7.8 m ahead on average at 4 m/s), which forgives lateral localization errors more.

``search="route"`` (the paper's ``local_planner_pid.py``): the closest waypoint (and the car's
closest point on the path) is the nearest of the whole route. ``search="window"`` (vlocbench's
option): only from ``search_behind_m`` behind to ``search_ahead_m`` ahead of the last closest
point, so that a route that passes the same street twice, or a wrong fix near another part of the
route, cannot make the target jump there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from vlocbench.config import require, require_one_of
from vlocbench.interfaces import Array
from vlocbench.nav.path import WaypointPath


@dataclass(frozen=True)
class LocalPlannerConfig:
    rule: Literal["paper", "band"] = "paper"
    min_lookahead_s: float = 0.9
    max_lookahead_s: float = 3.0
    # rule="band": floor of the lookahead band (at rest a time band is empty, and the car must
    # still set off)
    min_lookahead_m: float = 3.0
    # where in the band a recomputed target goes: 0 at its near edge, 1 at its far edge
    reselect_fraction: float = 1.0
    # where the closest waypoint is searched: the whole route, or a window around the last one
    search: Literal["route", "window"] = "route"
    # search="window": this far behind/ahead of the last closest point
    search_behind_m: float = 10.0
    search_ahead_m: float = 40.0

    def __post_init__(self) -> None:
        require_one_of(self.rule, ("paper", "band"), "local_planner.rule")
        require_one_of(self.search, ("route", "window"), "local_planner.search")
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
    """``target_speed_mps`` sets the paper rule's distances (the band rule uses the car's speed)."""

    def __init__(
        self,
        path: WaypointPath,
        config: LocalPlannerConfig | None = None,
        target_speed_mps: float = 4.0,
    ) -> None:
        require(target_speed_mps > 0, "target_speed_mps", "must be > 0")
        self.path = path
        self.config = config or LocalPlannerConfig()
        self.target_speed_mps = target_speed_mps
        self.reset()

    def reset(self, s_m: float = 0.0) -> None:
        """Restart from arc length ``s_m`` (a start or a re-initialization)."""
        self._s_m = float(np.clip(s_m, 0.0, self.path.length_m))
        self._target: int | None = None

    def band_m(self, speed_mps: float) -> tuple[float, float]:
        """rule="band": the lookahead band (near, far) in metres at ``speed_mps``."""
        c = self.config
        near = max(c.min_lookahead_s * speed_mps, c.min_lookahead_m)
        far = max(c.max_lookahead_s * speed_mps, near + float(np.max(np.diff(self.path.s_m))))
        return near, far

    def step(self, xy: Array, speed_mps: float) -> LocalTarget:
        """Target for a car believed to be at ``xy`` (2,) moving at ``speed_mps``."""
        c, path = self.config, self.path
        if c.search == "window":
            first, last = path.window(self._s_m, c.search_behind_m, c.search_ahead_m)
        else:
            first, last = 0, len(path) - 1
        proj = path.project(xy, first, last)
        self._s_m = proj.s_m
        if c.rule == "paper":
            self._step_paper(xy, first, last)
        else:
            self._step_band(abs(speed_mps))
        assert self._target is not None
        return LocalTarget(
            index=self._target,
            xy=path.xy[self._target],
            s_closest_m=self._s_m,
            remaining_m=path.length_m - self._s_m,
            offset_m=proj.distance_m,
        )

    def _step_paper(self, xy: Array, first: int, last: int) -> None:
        c, wp = self.config, self.path.xy
        near = c.min_lookahead_s * self.target_speed_mps
        far = c.max_lookahead_s * self.target_speed_mps

        def distance(i: int) -> float:
            return float(np.hypot(*(wp[i] - xy)))

        def closest() -> int:
            if distance(len(wp) - 1) <= near:
                return len(wp) - 1
            return first + int(np.argmin(np.linalg.norm(wp[first : last + 1] - xy, axis=1)))

        if self._target is None:
            self._target = closest()
        while self._target < len(wp) - 1 and distance(self._target) < near:
            self._target += 1
        if distance(self._target) > far:
            self._target = closest()

    def _step_band(self, speed_mps: float) -> None:
        c, path = self.config, self.path
        near, far = self.band_m(speed_mps)
        if self._s_m + near >= path.length_m:
            self._target = len(path) - 1
        elif self._target is None or not (near <= path.s_m[self._target] - self._s_m <= far):
            goal_s = self._s_m + near + c.reselect_fraction * (far - near)
            # the last waypoint not beyond goal_s, but never closer than the band's near edge
            idx = int(np.searchsorted(path.s_m, goal_s, side="right")) - 1
            self._target = max(idx, path.index_at(self._s_m + near))
