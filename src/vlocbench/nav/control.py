"""PID control of speed and heading, with outputs in the vehicle's control ranges.

The defaults are the paper's controller (CARLA's ``VehiclePIDController`` as its code runs it at
20 Hz): longitudinal, a PID on the speed error in km/h (Kp 0.206, Ki 0.0206, Kd 0.515) whose
integral is the sum of the errors of all steps (clipped to +-40) and whose derivative is the change
of the error per step; its output is the throttle in [0, 1], and it never brakes. Lateral, a P
controller (Kp 0.9) on the heading error (rad) from the car to its target waypoint; the output is
the normalized steering command (+ = left).

Options (vlocbench's own): gains per second (``time_base="second"``), braking when the output is
negative (``brake=True``), and slowing down to stop at the goal (``stop_decel_mps2``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from vlocbench.config import require, require_one_of
from vlocbench.geometry import wrap_angle
from vlocbench.interfaces import Array, Control

MPS_TO_KMH = 3.6


@dataclass(frozen=True)
class PidGains:
    """``time_base="step"``: the integral is the sum of the errors and the derivative the change of
    the error per control step (CARLA's controller, the paper's gains); ``"second"``: the integral
    of the error over time (error * s) and its rate of change per second."""

    kp: float
    ki: float = 0.0
    kd: float = 0.0
    integral_limit: float = 40.0  # anti-windup bound of the integral's state, in its time base
    time_base: Literal["step", "second"] = "step"

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            require(getattr(self, name) >= 0, f"pid.{name}", "must be >= 0")
        require(self.integral_limit > 0, "pid.integral_limit", "must be > 0")
        require_one_of(self.time_base, ("step", "second"), "pid.time_base")


class Pid:
    """Discrete PID called every ``dt_s``; the output is clipped to [``lo``, ``hi``]."""

    def __init__(self, gains: PidGains, dt_s: float, lo: float = -1.0, hi: float = 1.0) -> None:
        require(dt_s > 0, "dt_s", "must be > 0")
        self.gains, self.dt_s, self.lo, self.hi = gains, dt_s, lo, hi
        self.reset()

    def reset(self) -> None:
        self._integral = 0.0
        self._previous: float | None = None

    def step(self, error: float) -> float:
        g = self.gains
        per = self.dt_s if g.time_base == "second" else 1.0
        self._integral = float(
            np.clip(self._integral + error * per, -g.integral_limit, g.integral_limit)
        )
        # no derivative kick on the first step after a reset
        derivative = 0.0 if self._previous is None else (error - self._previous) / per
        self._previous = error
        return float(
            np.clip(g.kp * error + g.ki * self._integral + g.kd * derivative, self.lo, self.hi)
        )


@dataclass(frozen=True)
class ControllerConfig:
    target_speed_mps: float = 4.0
    # the paper's gains on km/h, per 20 Hz control step
    longitudinal: PidGains = field(default_factory=lambda: PidGains(0.206, 0.0206, 0.515, 40.0))
    lateral: PidGains = field(default_factory=lambda: PidGains(0.9, integral_limit=400.0))
    max_throttle: float = 1.0
    brake: bool = False  # True: a negative speed-PID output brakes (the paper's only lifts off)
    max_brake: float = 0.5
    max_steer: float = 1.0
    # slow down to stop at the goal: speed <= sqrt(2 * stop_decel * remaining distance); null:
    # drive through at the target speed, as the paper's (an episode ends at the goal)
    stop_decel_mps2: float | None = None

    def __post_init__(self) -> None:
        require(self.target_speed_mps > 0, "controller.target_speed_mps", "must be > 0")
        for name in ("max_throttle", "max_brake", "max_steer"):
            v = getattr(self, name)
            require(0 < v <= 1, f"controller.{name}", f"must be in (0, 1], got {v}")
        require(
            self.stop_decel_mps2 is None or self.stop_decel_mps2 > 0,
            "controller.stop_decel_mps2",
            "must be > 0 or null",
        )


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
        if c.stop_decel_mps2 is None:
            return c.target_speed_mps
        return min(c.target_speed_mps, float(np.sqrt(2 * c.stop_decel_mps2 * max(remaining_m, 0))))

    def step(
        self,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        speed_mps: float,
        target_xy: Array,
        remaining_m: float,
    ) -> Control:
        """Command for a car believed at (x, y, yaw) with ``speed_mps``, heading for ``target_xy``."""
        c = self.config
        error_kmh = (self.target_speed_mps(remaining_m) - speed_mps) * MPS_TO_KMH
        accel = self.speed_pid.step(error_kmh)
        steer = self.heading_pid.step(heading_error_rad(x_m, y_m, yaw_rad, target_xy))
        if accel >= 0 or not c.brake:
            return Control(min(max(accel, 0.0), c.max_throttle), steer, 0.0)
        return Control(0.0, steer, min(-accel, c.max_brake))
