"""PID control of speed and heading, with outputs in the vehicle's control ranges.

Longitudinal: a PID on the speed error in km/h (the paper's gains were tuned in km/h) whose output
in [-1, 1] becomes throttle (>= 0) or brake (< 0). Lateral: a PID on the heading error (rad) from
the car to its target waypoint; the output is the normalized steering command (+ = left).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vlocbench.config import require
from vlocbench.geometry import wrap_angle
from vlocbench.nav.path import Array

MPS_TO_KMH = 3.6


@dataclass(frozen=True)
class PidGains:
    kp: float
    ki: float = 0.0
    kd: float = 0.0
    integral_limit: float = 10.0  # anti-windup bound of the integral term's state (error * s)

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            require(getattr(self, name) >= 0, f"pid.{name}", "must be >= 0")
        require(self.integral_limit > 0, "pid.integral_limit", "must be > 0")


class Pid:
    """Discrete PID at a fixed step ``dt_s``; the output is clipped to [``lo``, ``hi``]."""

    def __init__(self, gains: PidGains, dt_s: float, lo: float = -1.0, hi: float = 1.0) -> None:
        require(dt_s > 0, "dt_s", "must be > 0")
        self.gains, self.dt_s, self.lo, self.hi = gains, dt_s, lo, hi
        self.reset()

    def reset(self) -> None:
        self._integral = 0.0
        self._previous: float | None = None

    def step(self, error: float) -> float:
        g = self.gains
        self._integral = float(
            np.clip(self._integral + error * self.dt_s, -g.integral_limit, g.integral_limit)
        )
        # no derivative kick on the first step after a reset
        derivative = 0.0 if self._previous is None else (error - self._previous) / self.dt_s
        self._previous = error
        return float(
            np.clip(g.kp * error + g.ki * self._integral + g.kd * derivative, self.lo, self.hi)
        )


@dataclass(frozen=True)
class ControllerConfig:
    target_speed_mps: float = 4.0
    # the paper's gains (Kp 0.206, Ki 0.0206, Kd 0.515 on km/h) with its Kd read per 20 Hz control
    # step, i.e. 0.515 * 0.05 s per second: per second, Kd 0.515 makes the loop oscillate
    longitudinal: PidGains = field(default_factory=lambda: PidGains(0.206, 0.0206, 0.02575))
    lateral: PidGains = field(default_factory=lambda: PidGains(0.9))
    max_throttle: float = 0.75
    max_brake: float = 0.5
    max_steer: float = 1.0
    # slow down to stop at the goal: speed <= sqrt(2 * stop_decel * remaining distance)
    stop_decel_mps2: float = 1.0

    def __post_init__(self) -> None:
        require(self.target_speed_mps > 0, "controller.target_speed_mps", "must be > 0")
        for name in ("max_throttle", "max_brake", "max_steer"):
            v = getattr(self, name)
            require(0 < v <= 1, f"controller.{name}", f"must be in (0, 1], got {v}")
        require(self.stop_decel_mps2 > 0, "controller.stop_decel_mps2", "must be > 0")


@dataclass(frozen=True)
class ControlCommand:
    """Throttle and brake in [0, 1], steer in [-1, 1] (+ = left), as the vehicle takes them."""

    throttle: float
    steer: float
    brake: float


def heading_error_rad(x_m: float, y_m: float, yaw_rad: float, target_xy: Array) -> float:
    """Signed angle from the car's heading to the direction of ``target_xy`` (+ = to the left)."""
    bearing = np.arctan2(target_xy[1] - y_m, target_xy[0] - x_m)
    return float(wrap_angle(bearing - yaw_rad))


class VehicleController:
    def __init__(self, config: ControllerConfig, dt_s: float) -> None:
        self.config = config
        self.speed_pid = Pid(config.longitudinal, dt_s)
        self.heading_pid = Pid(config.lateral, dt_s, -config.max_steer, config.max_steer)

    def reset(self) -> None:
        self.speed_pid.reset()
        self.heading_pid.reset()

    def target_speed_mps(self, remaining_m: float) -> float:
        c = self.config
        return min(c.target_speed_mps, float(np.sqrt(2 * c.stop_decel_mps2 * max(remaining_m, 0))))

    def step(
        self,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        speed_mps: float,
        target_xy: Array,
        remaining_m: float,
    ) -> ControlCommand:
        """Command for a car believed at (x, y, yaw) with ``speed_mps``, heading for ``target_xy``."""
        c = self.config
        error_kmh = (self.target_speed_mps(remaining_m) - speed_mps) * MPS_TO_KMH
        accel = self.speed_pid.step(error_kmh)
        steer = self.heading_pid.step(heading_error_rad(x_m, y_m, yaw_rad, target_xy))
        if accel >= 0:
            return ControlCommand(min(accel, c.max_throttle), steer, 0.0)
        return ControlCommand(0.0, steer, min(-accel, c.max_brake))
