"""Planar EKF fusing wheel odometry with (late) absolute pose measurements.

State (6,): x m, y m, yaw rad, v m/s, w rad/s, a m/s^2. The defaults are the paper's filter
(robot_localization's ``ekf_node`` in 2D mode, as configured in its code):

- ``odometry_fusion="twist"``: speed, yaw rate and acceleration are states (robot_localization's
  motion model: constant acceleration along the heading, constant yaw rate), and each odometry
  reading is a twist measurement of (v, w) with the covariance the paper's wheel-odometry node
  publishes (its noise model's sigmas at 4 m/s, 0.16 and 0.24, written into the variance slots).
  ``"input"`` (vlocbench's own): the readings drive the prediction as a control input and their
  noise enters through the input Jacobian (the acceleration state stays 0).
- process noise per second x, y 0.05, yaw 0.06, v 0.025, w 0.02, a 0.01 (robot_localization
  scales its matrix by the time step); initial covariance 1e-9; pose measurements with covariance
  0.1. The filter's lateral velocity is left out: it tracks the rear axle, which has none.
- gating by Mahalanobis distance 20 alone (the paper's text says "20 m"; its code sets
  ``pose0_rejection_threshold: 20``). ``metric_gate_m`` adds a gate in metres.
- ``late_measurements="current"``: ``smooth_lagged_data`` off, so a pose stamped in the past
  corrects the current state (the lag the paper discusses). ``"replay"``: the filter keeps a
  history, inserts the measurement at its stamp and replays what came after, so it lands exactly
  as if it had arrived on time.
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from vlocbench.config import require, require_one_of
from vlocbench.geometry import wrap_angle
from vlocbench.interfaces import Array
from vlocbench.nav.odometry import OdometryReading, integrate_planar

_N = 6  # x, y, yaw, v, w, a
_H_POSE = np.eye(3, _N)
_H_TWIST = np.eye(_N)[3:5]
_KNOWN_VAR = 1e-9  # variance of v and w at a (re)start: the car's motion is known

OdometryFusion = Literal["twist", "input"]
LateMeasurements = Literal["current", "replay"]


@dataclass(frozen=True)
class EkfConfig:
    odometry_fusion: OdometryFusion = "twist"
    late_measurements: LateMeasurements = "current"
    position_var_m2: float = 0.1  # default covariance of a pose measurement (the paper's 0.1)
    yaw_var_rad2: float = 0.1
    mahalanobis_gate: float | None = 20.0  # reject when sqrt(r' S^-1 r) is at least this
    metric_gate_m: float | None = None  # reject when the position innovation exceeds this
    process_position_var_m2ps: float = 0.05  # unmodelled motion, per second of prediction
    process_yaw_var_rad2ps: float = 0.06
    process_speed_var_m2ps3: float = 0.025  # twist fusion: how fast v may change, (m/s)^2 per s
    process_yaw_rate_var_rad2ps3: float = 0.02
    process_accel_var_m2ps5: float = 0.01
    # twist fusion: the variance of a reading's speed and yaw rate; null: each reading's own
    # (the noise model's at its speed) instead of the paper's fixed values
    twist_speed_var_m2ps2: float | None = 0.16
    twist_yaw_rate_var_rad2ps2: float | None = 0.24
    initial_position_var_m2: float = 1e-9
    initial_yaw_var_rad2: float = 1e-9
    history_s: float = 10.0  # late_measurements="replay": how late a measurement may be

    def __post_init__(self) -> None:
        require_one_of(self.odometry_fusion, ("twist", "input"), "ekf.odometry_fusion")
        require_one_of(self.late_measurements, ("current", "replay"), "ekf.late_measurements")
        for name in (
            "position_var_m2",
            "yaw_var_rad2",
            "process_position_var_m2ps",
            "process_yaw_var_rad2ps",
            "process_speed_var_m2ps3",
            "process_yaw_rate_var_rad2ps3",
            "process_accel_var_m2ps5",
            "initial_position_var_m2",
            "initial_yaw_var_rad2",
        ):
            require(getattr(self, name) > 0, f"ekf.{name}", "must be > 0")
        for name in (
            "mahalanobis_gate",
            "metric_gate_m",
            "twist_speed_var_m2ps2",
            "twist_yaw_rate_var_rad2ps2",
        ):
            v = getattr(self, name)
            require(v is None or v > 0, f"ekf.{name}", "must be > 0 or null")
        require(self.history_s > 0, "ekf.history_s", "must be > 0")

    def pose_covariance(self) -> Array:
        """(3, 3) default covariance of a pose measurement."""
        return np.diag([self.position_var_m2, self.position_var_m2, self.yaw_var_rad2])


# vlocbench's own filter before it followed the paper: odometry as the prediction's input, a
# filter that trusts its motion model (small process noise), late poses inserted at their stamp,
# and a 20 m gate besides the Mahalanobis one. A named option (``ekf: {...}`` in an episode config).
VLOCBENCH_EKF = EkfConfig(
    odometry_fusion="input",
    late_measurements="replay",
    metric_gate_m=20.0,
    process_position_var_m2ps=1e-3,
    process_yaw_var_rad2ps=1e-4,
    initial_position_var_m2=0.01,
    initial_yaw_var_rad2=1e-3,
)


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
    dt_s: float  # > 0: a prediction over dt_s ending at time_s with its odometry; 0: a measurement
    odometry: OdometryReading | None
    measurement: PoseMeasurement | None


class Ekf:
    def __init__(self, config: EkfConfig | None = None) -> None:
        self.config = config or EkfConfig()
        self.reset(0.0, 0.0, 0.0, 0.0)

    def reset(
        self,
        x_m: float,
        y_m: float,
        yaw_rad: float,
        time_s: float,
        speed_mps: float = 0.0,
        yaw_rate_radps: float = 0.0,
    ) -> None:
        """Start over at a known pose and motion (at rest by default: a start or a
        re-initialization)."""
        c = self.config
        self.x = np.array([x_m, y_m, yaw_rad, speed_mps, yaw_rate_radps, 0.0])
        self.P = np.diag(
            [c.initial_position_var_m2] * 2 + [c.initial_yaw_var_rad2] + [_KNOWN_VAR] * 3
        )
        self.time_s = time_s
        # late_measurements="replay": (event, state before it, covariance before it), in time order
        self._history: deque[tuple[_Event, Array, Array]] = deque()
        self._oldest_s = time_s  # the earliest time whose state the history can restore

    @property
    def pose(self) -> tuple[float, float, float]:
        return float(self.x[0]), float(self.x[1]), float(self.x[2])

    @property
    def speed_mps(self) -> float:
        """The filter's speed: filtered (twist fusion) or the last reading (input)."""
        return float(self.x[3])

    def _motion(self, v: float, w: float, a: float, dt_s: float) -> tuple[Array, Array]:
        """Motion of the pose at speed v, yaw rate w and acceleration a over ``dt_s``, along the
        mid-step heading: the new pose (3,) and its Jacobian (3, 6) with respect to the state."""
        x, y, yaw = self.x[:3]
        heading = yaw + 0.5 * w * dt_s
        c, s = np.cos(heading), np.sin(heading)
        d = v * dt_s + 0.5 * a * dt_s**2  # distance travelled
        J = np.array(
            [
                [1, 0, -d * s, c * dt_s, -0.5 * d * s * dt_s, 0.5 * c * dt_s**2],
                [0, 1, d * c, s * dt_s, 0.5 * d * c * dt_s, 0.5 * s * dt_s**2],
                [0, 0, 1, 0, dt_s, 0],
            ]
        )
        # the mean speed over the step, d / dt, along the mid-step heading
        return np.array(integrate_planar(x, y, yaw, d / dt_s, w, dt_s)), J

    def _process_noise(self, dt_s: float) -> Array:
        c = self.config
        q = [c.process_position_var_m2ps] * 2 + [c.process_yaw_var_rad2ps]
        q += [c.process_speed_var_m2ps3, c.process_yaw_rate_var_rad2ps3, c.process_accel_var_m2ps5]
        return np.diag(q) * dt_s

    def _predict_input(self, odometry: OdometryReading, dt_s: float) -> None:
        v, w = odometry.speed_mps, odometry.yaw_rate_radps
        pose, J = self._motion(v, w, 0.0, dt_s)
        F = np.zeros((_N, _N))  # velocities are replaced by the readings: zero rows/columns
        F[:3, :3] = J[:, :3]
        G = np.zeros((_N, 2))  # d state / d (v, w)
        G[:3] = J[:, 3:5]
        G[3:5] = np.eye(2)
        U = np.diag([odometry.speed_var, odometry.yaw_rate_var])
        Q = self._process_noise(dt_s)
        Q[3:, 3:] = 0.0
        self.x = np.array([*pose, v, w, 0.0])
        self.P = F @ self.P @ F.T + G @ U @ G.T + Q

    def _predict_twist(self, odometry: OdometryReading, dt_s: float) -> None:
        c = self.config
        v, w, a = (float(value) for value in self.x[3:])
        pose, J = self._motion(v, w, a, dt_s)
        F = np.eye(_N)
        F[:3] = J
        F[3, 5] = dt_s
        self.x = np.array([*pose, v + a * dt_s, w, a])
        self.P = F @ self.P @ F.T + self._process_noise(dt_s)
        # then the reading, a measurement of (v, w) at the end of the step
        R = np.diag(
            [
                odometry.speed_var if c.twist_speed_var_m2ps2 is None else c.twist_speed_var_m2ps2,
                odometry.yaw_rate_var
                if c.twist_yaw_rate_var_rad2ps2 is None
                else c.twist_yaw_rate_var_rad2ps2,
            ]
        )
        R = np.maximum(R, np.eye(2) * 1e-9)  # a reading at rest has no speed noise
        r = np.array([odometry.speed_mps, odometry.yaw_rate_radps]) - self.x[3:5]
        self._correct(_H_TWIST, r, R)

    def _correct(
        self, H: Array, r: Array, R: Array, S_inv: NDArray[np.floating] | None = None
    ) -> None:
        if S_inv is None:
            S_inv = np.linalg.inv(H @ self.P @ H.T + R)
        K = self.P @ H.T @ S_inv
        self.x = self.x + K @ r
        self.x[2] = wrap_angle(self.x[2])
        A = np.eye(_N) - K @ H  # Joseph form keeps P symmetric positive definite
        self.P = A @ self.P @ A.T + K @ R @ K.T

    def _update(self, m: PoseMeasurement) -> UpdateOutcome:
        c = self.config
        r = np.array([m.x_m - self.x[0], m.y_m - self.x[1], wrap_angle(m.yaw_rad - self.x[2])])
        S_inv = np.linalg.inv(_H_POSE @ self.P @ _H_POSE.T + m.covariance)
        d = float(np.sqrt(max(r @ S_inv @ r, 0.0)))
        innovation_m = float(np.hypot(r[0], r[1]))
        if c.metric_gate_m is not None and innovation_m > c.metric_gate_m:
            return UpdateOutcome(False, d, innovation_m, f"{innovation_m:.1f} m from the estimate")
        if c.mahalanobis_gate is not None and d >= c.mahalanobis_gate:
            return UpdateOutcome(False, d, innovation_m, f"Mahalanobis distance {d:.1f}")
        self._correct(_H_POSE, r, m.covariance, S_inv)
        return UpdateOutcome(True, d, innovation_m)

    def _apply(self, event: _Event) -> UpdateOutcome | None:
        if self.config.late_measurements == "replay":
            self._history.append((event, self.x.copy(), self.P.copy()))
        self.time_s = event.time_s
        if event.measurement is not None:
            return self._update(event.measurement)
        assert event.odometry is not None
        if self.config.odometry_fusion == "twist":
            self._predict_twist(event.odometry, event.dt_s)
        else:
            self._predict_input(event.odometry, event.dt_s)
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
        """Fuse a pose taken at ``m.time_s`` (<= now): at the current state, or at its stamp with
        the later steps replayed (``late_measurements``)."""
        if m.time_s > self.time_s + 1e-9:
            raise ValueError(f"measurement at {m.time_s} s is in the future (now {self.time_s} s)")
        if self.config.late_measurements == "current":
            return self._update(m)
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
