"""Wheel odometry: the car's speed and yaw rate with seeded Gaussian noise, and its drift.

Noise model (the paper's): sigma_v = a * |v| and sigma_w = b * |v| + c, with a = b = 0.04 and
c = 0.08 rad/s, drawn independently for every reading.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vlocbench.config import require
from vlocbench.geometry import wrap_angle
from vlocbench.interfaces import Array


@dataclass(frozen=True)
class OdometryNoise:
    speed_sigma_per_mps: float = 0.04  # a: sigma_v = a * |v|
    yaw_rate_sigma_per_mps: float = 0.04  # b: sigma_w = b * |v| + c (rad/s per m/s)
    yaw_rate_sigma_radps: float = 0.08  # c

    def __post_init__(self) -> None:
        for name in ("speed_sigma_per_mps", "yaw_rate_sigma_per_mps", "yaw_rate_sigma_radps"):
            require(getattr(self, name) >= 0, f"odometry.{name}", "must be >= 0")

    def sigmas(self, speed_mps: float) -> tuple[float, float]:
        """(sigma_v m/s, sigma_w rad/s) at ``speed_mps``."""
        v = abs(speed_mps)
        return (
            self.speed_sigma_per_mps * v,
            self.yaw_rate_sigma_per_mps * v + self.yaw_rate_sigma_radps,
        )


@dataclass(frozen=True)
class OdometryReading:
    """A reading and the variances of its noise (what an EKF needs)."""

    speed_mps: float
    yaw_rate_radps: float
    speed_var: float
    yaw_rate_var: float


class WheelOdometry:
    """Noisy readings of the true motion; the noise stream is fixed by ``seed``."""

    def __init__(self, noise: OdometryNoise | None = None, seed: int = 0) -> None:
        self.noise = noise or OdometryNoise()
        self.rng = np.random.default_rng(seed)

    def read(self, speed_mps: float, yaw_rate_radps: float) -> OdometryReading:
        sigma_v, sigma_w = self.noise.sigmas(speed_mps)
        dv, dw = self.rng.standard_normal(2)
        return OdometryReading(
            speed_mps + sigma_v * dv, yaw_rate_radps + sigma_w * dw, sigma_v**2, sigma_w**2
        )


def integrate_planar(
    x_m: float, y_m: float, yaw_rad: float, speed_mps: float, yaw_rate_radps: float, dt_s: float
) -> tuple[float, float, float]:
    """Unicycle motion over ``dt_s`` at constant speed and yaw rate, at the mid-step heading."""
    heading = yaw_rad + 0.5 * yaw_rate_radps * dt_s
    return (
        x_m + speed_mps * np.cos(heading) * dt_s,
        y_m + speed_mps * np.sin(heading) * dt_s,
        float(wrap_angle(yaw_rad + yaw_rate_radps * dt_s)),
    )


@dataclass(frozen=True)
class Drift:
    """Dead-reckoning drift at the end of a drive of ``distance_m``."""

    distance_m: float
    position_error_m: float
    yaw_error_deg: float

    @property
    def position_percent(self) -> float:
        return 100.0 * self.position_error_m / self.distance_m

    @property
    def yaw_deg_per_m(self) -> float:
        return self.yaw_error_deg / self.distance_m


def dead_reckoning_drift(
    true_xy_yaw: Array,
    speeds_mps: Array,
    yaw_rates_radps: Array,
    dt_s: float,
    odometry: WheelOdometry,
) -> Drift:
    """Dead-reckon from the first true pose with noisy readings of the true motion.

    ``true_xy_yaw``: (N + 1, 3) poses at each step; ``speeds_mps``, ``yaw_rates_radps``: (N,) the
    true motion over each step.
    """
    x, y, yaw = (float(v) for v in true_xy_yaw[0])
    for v, w in zip(speeds_mps, yaw_rates_radps):
        r = odometry.read(float(v), float(w))
        x, y, yaw = integrate_planar(x, y, yaw, r.speed_mps, r.yaw_rate_radps, dt_s)
    distance = float(np.sum(np.abs(speeds_mps)) * dt_s)
    end = true_xy_yaw[-1]
    return Drift(
        distance_m=distance,
        position_error_m=float(np.hypot(x - end[0], y - end[1])),
        yaw_error_deg=float(np.degrees(np.abs(wrap_angle(yaw - end[2])))),
    )
