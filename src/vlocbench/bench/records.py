"""What an episode produces: typed, plain-data records (numbers and numpy arrays, no I/O)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import Any, Literal, get_args

import numpy as np

from vlocbench.interfaces import Array

# an experiment's drives: the ground-truth drive scored for recall, the drive navigated on the
# method's poses, and the drive on wheel odometry alone
EpisodeKind = Literal["recall", "failure", "baseline"]
EPISODE_KINDS: tuple[str, ...] = get_args(EpisodeKind)
# (position m, rotation deg): a returned pose beyond this is wrong (the paper's coarsest recall)
WRONG_THRESHOLD: tuple[float, float] = (5.0, 10.0)


def per_km(count: float, covered_m: float) -> float:
    """``count`` failures over ``covered_m`` of route, per km; at least one metre, so that a car
    that never got going has a finite, huge rate."""
    return count / (max(covered_m, 1.0) / 1000.0)


@dataclass(frozen=True, kw_only=True)
class LocalizationRecord:
    """One localization call: the image time, the estimate against the truth at that time.

    Errors are NaN when the call failed. ``position_error_m`` / ``yaw_error_deg``: planar (x, y,
    yaw); ``position_error_3d_m`` / ``rotation_error_deg``: 6-DoF, the 3D distance and the full
    rotation angle between the true and estimated vehicle (so camera) orientation, as the paper's
    evaluator measures them. ``z_m``, ``roll_rad``, ``pitch_rad`` complete the estimate to 6-DoF
    (the car drives on flat ground, so the truth's are 0). ``ekf_*``: the filter's estimate at
    the image time (before this estimate was fused). ``fused``: True/False once the EKF accepted/rejected it, None when it was
    never offered (failure, or a re-initialization came first).
    """

    time_s: float
    success: bool
    x_m: float
    y_m: float
    yaw_rad: float
    z_m: float
    roll_rad: float
    pitch_rad: float
    true_x_m: float
    true_y_m: float
    true_yaw_rad: float
    ekf_x_m: float
    ekf_y_m: float
    ekf_yaw_rad: float
    position_error_m: float
    yaw_error_deg: float
    position_error_3d_m: float
    rotation_error_deg: float
    compute_time_s: float
    latency_s: float
    fused: bool | None
    reason: str
    # place recognition: from the true vehicle position to where the gallery's vehicle stood for
    # each of the retrieval's best images, best first (m); empty for localizers without retrieval
    retrieval_distances_m: tuple[float, ...] = ()
    retrieved_images: tuple[str, ...] = ()  # the gallery images retrieval chose, best first
    # the answer's own (3, 3) covariance of x, y, yaw (m^2, m rad, rad^2), row by row; empty when
    # the localizer gave none and the EKF used its default (EkfConfig.pose_covariance)
    covariance: tuple[float, ...] = ()
    # PnP inliers of the answer (0 on failure, or when the localizer reports none): what a
    # ``localizer.min_inliers`` would have been compared with
    inliers: int = 0
    # the localizer's time by stage (s), as it reports it: a map localizer's features, retrieval,
    # matching and pnp (together its compute_time_s); empty for localizers that report none
    stage_s: dict[str, float] = field(default_factory=dict)


def localization_columns(locs: Sequence[LocalizationRecord]) -> dict[str, list[Any]]:
    """Records as columns, by field name (the stored table's layout)."""
    names = [f.name for f in fields(LocalizationRecord)]
    return {n: [getattr(x, n) for x in locs] for n in names} if locs else {}


@dataclass(frozen=True, kw_only=True)
class Reinitialization:
    """A navigation failure and where the car was put back.

    (x_m, y_m): where the car truly was when it failed; ``resume_index``/``resume_s_m``: the route
    waypoint (and its arc length) it restarted from.
    """

    time_s: float
    x_m: float
    y_m: float
    cause: str
    detail: str
    resume_index: int
    resume_s_m: float


@dataclass(frozen=True)
class Segment:
    """A stretch of the route driven without failure, by arc length."""

    start_s_m: float
    end_s_m: float

    @property
    def length_m(self) -> float:
        return self.end_s_m - self.start_s_m


@dataclass(frozen=True, kw_only=True)
class Trajectory:
    """Per-step columns, all (N,): time, true pose, EKF pose and its covariance (the upper
    triangle of the (3, 3) over x, y, yaw), true speed, and the wheel odometry the EKF got for the
    step that starts there (NaN in the last row)."""

    time_s: Array
    true_x_m: Array
    true_y_m: Array
    true_yaw_rad: Array
    ekf_x_m: Array
    ekf_y_m: Array
    ekf_yaw_rad: Array
    ekf_cov_xx_m2: Array
    ekf_cov_xy_m2: Array
    ekf_cov_xyaw_mrad: Array
    ekf_cov_yy_m2: Array
    ekf_cov_yyaw_mrad: Array
    ekf_cov_yawyaw_rad2: Array
    speed_mps: Array
    odometry_speed_mps: Array
    odometry_yaw_rate_radps: Array

    @property
    def ekf_position_error_m(self) -> Array:
        return np.hypot(self.ekf_x_m - self.true_x_m, self.ekf_y_m - self.true_y_m)


@dataclass(frozen=True, kw_only=True)
class EpisodeResult:
    """One drive of a route. Distances in metres, times in seconds (simulated unless ``wall``).

    An episode that runs out of time covered only part of the route: its failure rate divides its
    failures by the route it covered (up to the farthest waypoint reached), never by the whole
    route. With ``timeout_is_failure`` (vlocbench's option) running out of time is one failure
    more (cause ``timeout``); the paper's harness counted none (it ran a scenario again when it
    overran its budget).
    """

    episode_config_hash: str  # config.config_hash of the EpisodeConfig it ran with
    mode: str
    localizer: str
    route_length_m: float
    route_covered_m: float  # the route up to the farthest point reached (all of it if completed)
    distance_driven_m: float
    completed: bool  # reached the goal (else it ran out of time)
    timeout_is_failure: bool = False
    sim_time_s: float
    wall_time_s: float
    reinitializations: tuple[Reinitialization, ...]
    lock_losses_s: tuple[float, ...]  # ground_truth drives: when the EKF was reset at the truth
    segments: tuple[Segment, ...]
    tracking_error_mean_m: float  # mean distance of the true position from the route
    final_drift_m: float  # EKF position error at the end
    localizations: tuple[LocalizationRecord, ...]
    trajectory: Trajectory

    @property
    def failure_causes(self) -> tuple[str, ...]:
        """The cause of each failure, a time-out that counts as one (if any) last."""
        causes = tuple(r.cause for r in self.reinitializations)
        return causes if self.completed or not self.timeout_is_failure else (*causes, "timeout")

    @property
    def failures(self) -> int:
        return len(self.failure_causes)

    @property
    def failures_per_km(self) -> float:
        """r / L_km: this episode's term of the failure rate F (L: the route it covered)."""
        return per_km(self.failures, self.route_covered_m)

    @property
    def real_time_factor(self) -> float:
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else float("inf")
