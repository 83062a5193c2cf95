"""Kinematic bicycle model driven by CARLA-style controls (pure numpy).

The reference point is the car's centre (slip angle from the centre-of-mass bicycle model with the
axles at +-wheelbase/2). Actuators have first-order lag; steering is also rate limited. Speed never
goes negative (there is no reverse gear).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from vlocbench.config import require
from vlocbench.geometry import planar_pose, wrap_angle
from vlocbench.interfaces import Array, Control


@dataclass(frozen=True)
class VehicleParams:
    """The car. The defaults are the paper's ``vehicle.tesla.model3`` as CARLA builds it: front
    wheels that steer up to 70 deg (CARLA's ``WheelPhysicsControl.max_steer_angle``), a 2.9 m
    wheelbase (the Model 3's 2.875 m). ``max_steer_deg: 35`` was vlocbench's car until December
    2026, a road car's usual lock."""

    wheelbase_m: float = 2.9
    max_steer_deg: float = 70.0
    max_steer_rate_deg_s: float = 120.0
    max_accel_mps2: float = 3.0
    max_brake_mps2: float = 8.0
    drag_per_s: float = 0.02  # rolling and air resistance, as a deceleration of drag * speed
    actuator_tau_s: float = 0.15  # first-order lag of steering and acceleration
    max_speed_mps: float = 25.0

    def __post_init__(self) -> None:
        require(self.wheelbase_m > 0, "vehicle.wheelbase_m", "must be > 0")
        require(0 < self.max_steer_deg < 80, "vehicle.max_steer_deg", "must be in (0, 80)")
        require(self.max_steer_rate_deg_s > 0, "vehicle.max_steer_rate_deg_s", "must be > 0")
        require(self.max_accel_mps2 > 0, "vehicle.max_accel_mps2", "must be > 0")
        require(self.max_brake_mps2 > 0, "vehicle.max_brake_mps2", "must be > 0")
        require(self.actuator_tau_s >= 0, "vehicle.actuator_tau_s", "must be >= 0")


@dataclass(frozen=True)
class VehicleState:
    x_m: float
    y_m: float
    yaw_rad: float
    speed_mps: float = 0.0
    yaw_rate_radps: float = 0.0
    steer_rad: float = 0.0
    accel_mps2: float = 0.0
    time_s: float = 0.0

    def world_from_vehicle(self) -> Array:
        return planar_pose(self.x_m, self.y_m, self.yaw_rad)


def step_vehicle(
    state: VehicleState, control: Control, params: VehicleParams, dt_s: float
) -> VehicleState:
    """Advance ``state`` by ``dt_s`` under ``control``."""
    lag = 1.0 if params.actuator_tau_s == 0 else min(1.0, dt_s / params.actuator_tau_s)
    max_steer = np.radians(params.max_steer_deg)
    steer_target = state.steer_rad + (control.steer * max_steer - state.steer_rad) * lag
    max_delta = np.radians(params.max_steer_rate_deg_s) * dt_s
    steer = float(np.clip(steer_target, state.steer_rad - max_delta, state.steer_rad + max_delta))
    accel_cmd = control.throttle * params.max_accel_mps2 - control.brake * params.max_brake_mps2
    accel = state.accel_mps2 + (accel_cmd - state.accel_mps2) * lag
    drag = params.drag_per_s * state.speed_mps
    speed = float(np.clip(state.speed_mps + (accel - drag) * dt_s, 0.0, params.max_speed_mps))
    beta = float(np.arctan(0.5 * np.tan(steer)))
    yaw_rate = speed * np.cos(beta) * np.tan(steer) / params.wheelbase_m
    # integrate at the mid-step heading (second order in dt for constant inputs)
    v_mid = 0.5 * (state.speed_mps + speed)
    heading = state.yaw_rad + 0.5 * yaw_rate * dt_s + beta
    return VehicleState(
        x_m=float(state.x_m + v_mid * np.cos(heading) * dt_s),
        y_m=float(state.y_m + v_mid * np.sin(heading) * dt_s),
        yaw_rad=float(wrap_angle(state.yaw_rad + yaw_rate * dt_s)),
        speed_mps=speed,
        yaw_rate_radps=float(yaw_rate),
        steer_rad=steer,
        accel_mps2=float(accel),
        time_s=state.time_s + dt_s,
    )


def at_rest(state: VehicleState, x_m: float, y_m: float, yaw_rad: float) -> VehicleState:
    """The car placed at a new pose, stopped (re-initialization)."""
    return dataclasses.replace(
        state,
        x_m=x_m,
        y_m=y_m,
        yaw_rad=yaw_rad,
        speed_mps=0.0,
        yaw_rate_radps=0.0,
        steer_rad=0.0,
        accel_mps2=0.0,
    )
