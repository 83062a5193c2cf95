"""Planar EKF fusing wheel odometry with (late) absolute pose measurements.

State (5,): x m, y m, yaw rad, v m/s, w rad/s. Odometry drives the prediction as a control input
(its noise enters through the input Jacobian), so with no measurements the filter dead-reckons.
Pose measurements (x, y, yaw with a 3x3 covariance) are gated by their Mahalanobis distance and,
optionally, by their metric distance from the estimate.

Measurements may arrive late: each one carries the time its image was taken. The filter keeps a
history of its predictions and updates; a late measurement is inserted at its stamp and everything
after it is replayed, so it lands exactly as if it had arrived on time.
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass

import numpy as np

from vlocbench.config import require
from vlocbench.geometry import wrap_angle
from vlocbench.nav.odometry import OdometryReading, integrate_planar
from vlocbench.nav.path import Array

_H_POSE = np.eye(3, 5)


@dataclass(frozen=True)
class EkfConfig:
    position_var_m2: float = 0.1  # default covariance of a pose measurement (the paper's 0.1)
    yaw_var_rad2: float = 0.1
    mahalanobis_gate: float | None = 20.0  # reject when sqrt(r' S^-1 r) exceeds this
    metric_gate_m: float | None = 20.0  # reject when the position innovation exceeds this
    process_position_var_m2ps: float = 1e-3  # unmodelled motion (m^2 per s)
    process_yaw_var_rad2ps: float = 1e-4
    initial_position_var_m2: float = 0.01
    initial_yaw_var_rad2: float = 1e-3
    history_s: float = 10.0  # how late a measurement may be

    def __post_init__(self) -> None:
        for name in (
            "position_var_m2",
            "yaw_var_rad2",
            "process_position_var_m2ps",
            "process_yaw_var_rad2ps",
            "initial_position_var_m2",
            "initial_yaw_var_rad2",
        ):
            require(getattr(self, name) > 0, f"ekf.{name}", "must be > 0")
        for name in ("mahalanobis_gate", "metric_gate_m"):
            v = getattr(self, name)
            require(v is None or v > 0, f"ekf.{name}", "must be > 0 or null (no gate)")
        require(self.history_s > 0, "ekf.history_s", "must be > 0")

    def pose_covariance(self) -> Array:
        """(3, 3) default covariance of a pose measurement."""
        return np.diag([self.position_var_m2, self.position_var_m2, self.yaw_var_rad2])


@dataclass(frozen=True)
class PoseMeasurement:
    """An absolute pose taken at ``time_s``; ``covariance`` (3, 3) over (x, y, yaw)."""

    time_s: float
    x_m: float
    y_m: float
    yaw_rad: float
    covariance: Array


@dataclass(frozen=True)
class UpdateOutcome:
    """What became of a measurement: ``accepted``, else ``reason`` says why not."""

    accepted: bool
    mahalanobis: float
    innovation_m: float
    reason: str = ""


@dataclass(frozen=True)
class _Event:
    time_s: float
    dt_s: float  # > 0: a prediction over dt_s ending at time_s; 0: a measurement
    odometry: OdometryReading | None
    measurement: PoseMeasurement | None


class Ekf:
    def __init__(self, config: EkfConfig | None = None) -> None:
        self.config = config or EkfConfig()
        self.reset(0.0, 0.0, 0.0, 0.0)

    def reset(self, x_m: float, y_m: float, yaw_rad: float, time_s: float) -> None:
        """Start over at a known pose, at rest (start and re-initialization)."""
        c = self.config
        self.x = np.array([x_m, y_m, yaw_rad, 0.0, 0.0])
        self.P = np.diag([c.initial_position_var_m2] * 2 + [c.initial_yaw_var_rad2, 1e-4, 1e-4])
        self.time_s = time_s
        # (event, state before it, covariance before it), in time order
        self._history: deque[tuple[_Event, Array, Array]] = deque()
        self._oldest_s = time_s  # the earliest time whose state the history can restore

    @property
    def pose(self) -> tuple[float, float, float]:
        return float(self.x[0]), float(self.x[1]), float(self.x[2])

    def _predict(self, odometry: OdometryReading, dt_s: float) -> None:
        x, y, yaw = self.x[:3]
        v, w = odometry.speed_mps, odometry.yaw_rate_radps
        nx, ny, nyaw = integrate_planar(x, y, yaw, v, w, dt_s)
        heading = yaw + 0.5 * w * dt_s
        c, s = np.cos(heading), np.sin(heading)
        F = np.zeros((5, 5))  # velocities are replaced by the readings: zero rows/columns
        F[:3, :3] = [[1, 0, -v * s * dt_s], [0, 1, v * c * dt_s], [0, 0, 1]]
        G = np.zeros((5, 2))  # d state / d (v, w)
        G[:, 0] = [c * dt_s, s * dt_s, 0, 1, 0]
        G[:, 1] = [-0.5 * v * s * dt_s**2, 0.5 * v * c * dt_s**2, dt_s, 0, 1]
        Q = np.diag(
            [self.config.process_position_var_m2ps * dt_s] * 2
            + [self.config.process_yaw_var_rad2ps * dt_s, 0, 0]
        )
        U = np.diag([odometry.speed_var, odometry.yaw_rate_var])
        self.x = np.array([nx, ny, nyaw, v, w])
        self.P = F @ self.P @ F.T + G @ U @ G.T + Q

    def _update(self, m: PoseMeasurement) -> UpdateOutcome:
        c = self.config
        r = np.array([m.x_m - self.x[0], m.y_m - self.x[1], wrap_angle(m.yaw_rad - self.x[2])])
        S = _H_POSE @ self.P @ _H_POSE.T + m.covariance
        S_inv = np.linalg.inv(S)
        d = float(np.sqrt(max(r @ S_inv @ r, 0.0)))
        innovation_m = float(np.hypot(r[0], r[1]))
        if c.metric_gate_m is not None and innovation_m > c.metric_gate_m:
            return UpdateOutcome(False, d, innovation_m, f"{innovation_m:.1f} m from the estimate")
        if c.mahalanobis_gate is not None and d > c.mahalanobis_gate:
            return UpdateOutcome(False, d, innovation_m, f"Mahalanobis distance {d:.1f}")
        K = self.P @ _H_POSE.T @ S_inv
        self.x = self.x + K @ r
        self.x[2] = wrap_angle(self.x[2])
        A = np.eye(5) - K @ _H_POSE  # Joseph form keeps P symmetric positive definite
        self.P = A @ self.P @ A.T + K @ m.covariance @ K.T
        return UpdateOutcome(True, d, innovation_m)

    def _apply(self, event: _Event) -> UpdateOutcome | None:
        self._history.append((event, self.x.copy(), self.P.copy()))
        self.time_s = event.time_s
        if event.measurement is not None:
            return self._update(event.measurement)
        assert event.odometry is not None
        self._predict(event.odometry, event.dt_s)
        return None

    def _forget(self) -> None:
        while self._history and self._history[0][0].time_s < self.time_s - self.config.history_s:
            self._oldest_s = self._history.popleft()[0].time_s

    def predict(self, odometry: OdometryReading, dt_s: float) -> None:
        """Advance by ``dt_s`` with an odometry reading of the motion over that step."""
        require(dt_s > 0, "dt_s", "must be > 0")
        self._apply(_Event(self.time_s + dt_s, dt_s, odometry, None))
        self._forget()

    def update(self, m: PoseMeasurement) -> UpdateOutcome:
        """Fuse a pose taken at ``m.time_s`` (<= now): applied at its stamp, later steps replayed."""
        if m.time_s > self.time_s + 1e-9:
            raise ValueError(f"measurement at {m.time_s} s is in the future (now {self.time_s} s)")
        if m.time_s < self._oldest_s - 1e-9:
            return UpdateOutcome(
                False, float("nan"), float("nan"), "older than the filter's history"
            )
        times = [e.time_s for e, _, _ in self._history]
        # after every event at or before the stamp (the prediction ending at it included)
        k = bisect.bisect_right(times, m.time_s + 1e-9)
        later = [self._history.pop() for _ in range(len(self._history) - k)][::-1]
        if later:
            _, self.x, self.P = later[0]
        outcome = self._apply(_Event(m.time_s, 0.0, None, m))
        assert outcome is not None
        for event, _, _ in later:
            self._apply(event)
        return outcome
