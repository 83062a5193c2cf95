"""Navigation failure detection: collisions (debounced), getting stuck, leaving the route.

The paper counts collisions alone (``causes=("collision",)``, the default); getting stuck and
leaving the route are options. Running out of time (``timeout``) is the episode's to decide.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from vlocbench.config import require, require_one_of

FailureCause = Literal["collision", "stuck", "off_route", "timeout"]
DETECTED_CAUSES: tuple[str, ...] = ("collision", "stuck", "off_route")


@dataclass(frozen=True)
class FailureConfig:
    causes: tuple[str, ...] = ("collision",)  # which of DETECTED_CAUSES end a segment
    # a collision within this distance and time of the last counted one is the same failure
    collision_debounce_m: float = 5.0
    collision_debounce_s: float = 5.0
    stuck_speed_mps: float = 0.2
    stuck_s: float = 10.0  # slower than stuck_speed_mps for this long
    off_route_m: float = 5.0
    off_route_s: float = 3.0  # farther than off_route_m from the route for this long

    def __post_init__(self) -> None:
        for cause in self.causes:
            require_one_of(cause, DETECTED_CAUSES, "failure.causes")
        require(len(set(self.causes)) == len(self.causes), "failure.causes", "lists a cause twice")
        for name in ("collision_debounce_m", "collision_debounce_s", "stuck_speed_mps"):
            require(getattr(self, name) >= 0, f"failure.{name}", "must be >= 0")
        for name in ("stuck_s", "off_route_m", "off_route_s"):
            require(getattr(self, name) > 0, f"failure.{name}", "must be > 0")


@dataclass(frozen=True)
class Failure:
    """A navigation failure at ``time_s`` where the car truly was (x_m, y_m)."""

    time_s: float
    x_m: float
    y_m: float
    cause: FailureCause
    detail: str = ""


class FailureDetector:
    """Feed it every step's collisions and true state; it says when navigation has failed."""

    def __init__(self, config: FailureConfig | None = None) -> None:
        self.config = config or FailureConfig()
        self._last_collision: Failure | None = None
        self.restart(0.0)

    def restart(self, time_s: float) -> None:
        """The car was (re)placed at ``time_s``: stuck and off-route timers start over."""
        self._slow_since = time_s
        self._off_since: float | None = None

    def collision(self, time_s: float, x_m: float, y_m: float, what: str) -> Failure | None:
        """A collision started; a failure unless it repeats the last one (debounce) or collisions
        are not counted."""
        c, last = self.config, self._last_collision
        if "collision" not in c.causes:
            return None
        if (
            last is not None
            and time_s - last.time_s <= c.collision_debounce_s
            and (x_m - last.x_m) ** 2 + (y_m - last.y_m) ** 2 <= c.collision_debounce_m**2
        ):
            return None
        self._last_collision = Failure(time_s, x_m, y_m, "collision", what)
        return self._last_collision

    def check(
        self, time_s: float, x_m: float, y_m: float, speed_mps: float, route_distance_m: float
    ) -> Failure | None:
        """Stuck or off the route for too long (true position and speed)."""
        c = self.config
        if speed_mps >= c.stuck_speed_mps:
            self._slow_since = time_s
        elif "stuck" in c.causes and time_s - self._slow_since >= c.stuck_s:
            return Failure(
                time_s, x_m, y_m, "stuck", f"below {c.stuck_speed_mps:g} m/s for {c.stuck_s:g} s"
            )
        if route_distance_m <= c.off_route_m:
            self._off_since = None
        elif self._off_since is None:
            self._off_since = time_s
        elif "off_route" in c.causes and time_s - self._off_since >= c.off_route_s:
            return Failure(
                time_s,
                x_m,
                y_m,
                "off_route",
                f"{route_distance_m:.1f} m from the route for {c.off_route_s:g} s",
            )
        return None
