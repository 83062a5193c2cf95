"""A drivable path: waypoints with arc length, and projection of positions onto it (pure numpy)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vlocbench.errors import ConfigError
from vlocbench.geometry import headings_of
from vlocbench.interfaces import Array


@dataclass(frozen=True)
class Projection:
    """Where a position lies relative to a path.

    ``segment``: index i of the closest segment (waypoint i to i + 1); ``s_m``: arc length of the
    foot point from the start; ``distance_m``: distance to the foot point (>= 0).
    """

    segment: int
    s_m: float
    distance_m: float


class WaypointPath:
    """Waypoints ``xy`` (N, 2), N >= 2, with headings ``yaw_rad`` (N,) and arc lengths ``s_m`` (N,)."""

    def __init__(self, xy: Array) -> None:
        xy = np.asarray(xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 2:
            raise ConfigError("path", f"needs (N >= 2, 2) waypoints, got shape {xy.shape}")
        seg = np.diff(xy, axis=0)
        seg_len = np.linalg.norm(seg, axis=1)
        if np.any(seg_len < 1e-9):
            raise ConfigError("path", "consecutive waypoints must differ")
        self.xy = xy
        self.s_m = np.concatenate([[0.0], np.cumsum(seg_len)])
        self.yaw_rad = headings_of(xy)
        self._seg_dir = seg / seg_len[:, None]
        self._seg_len = seg_len

    def __len__(self) -> int:
        return len(self.xy)

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])

    def project(self, xy: Array, first: int = 0, last: int | None = None) -> Projection:
        """Closest point of segments ``first`` .. ``last - 1`` (all by default) to position (2,)."""
        last = len(self.xy) - 1 if last is None else min(last, len(self.xy) - 1)
        first = min(max(first, 0), last - 1)
        d = np.asarray(xy, dtype=np.float64) - self.xy[first:last]
        t = np.clip(
            np.einsum("ij,ij->i", d, self._seg_dir[first:last]), 0.0, self._seg_len[first:last]
        )
        foot = self.xy[first:last] + self._seg_dir[first:last] * t[:, None]
        dist = np.linalg.norm(np.asarray(xy) - foot, axis=1)
        k = int(np.argmin(dist))
        return Projection(first + k, float(self.s_m[first + k] + t[k]), float(dist[k]))

    def head(self, length_m: float) -> WaypointPath:
        """The path up to the first waypoint at or past ``length_m`` (all of it when that is <= 0
        or beyond the end)."""
        if length_m <= 0 or length_m >= self.length_m:
            return self
        return WaypointPath(self.xy[: int(np.searchsorted(self.s_m, length_m)) + 1])

    def index_at(self, s_m: float) -> int:
        """The first waypoint at arc length >= ``s_m`` (the last one past the end)."""
        return min(int(np.searchsorted(self.s_m, s_m - 1e-9)), len(self.xy) - 1)

    def window(self, s_m: float, behind_m: float, ahead_m: float) -> tuple[int, int]:
        """Segment range [first, last) covering arc lengths ``s_m - behind_m`` .. ``s_m + ahead_m``."""
        first = max(0, int(np.searchsorted(self.s_m, s_m - behind_m)) - 1)
        last = int(np.searchsorted(self.s_m, s_m + ahead_m)) + 1
        return first, max(first + 1, min(last, len(self.xy) - 1))
