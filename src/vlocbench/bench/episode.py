"""The closed-loop episode: simulator, navigation stack and a localizer in one synchronous loop.

Every step of ``dt_s`` (0.05 s): deliver localization answers that are due, plan and control on the
pose the mode prescribes (``navigate``: the EKF's; ``ground_truth``: the true one), step the
simulator, feed the EKF the wheel odometry of that step, track progress and detect failures. A
failure re-initializes the car, the EKF and the planner at the farthest route waypoint reached.

Localization runs at ``localization_rate_hz`` on images of the true pose. An answer is stamped with
its image time and reaches the EKF ``latency`` later (none, fixed, or the measured compute time);
while a query is in flight the localizer takes no new one.

The EKF tracks the rear axle, the point wheel odometry measures: it moves along the car's heading,
whereas the car's centre slips sideways in turns (by up to 10 degrees at the route's corners), which
a unicycle motion model would mistake for drift. Poses go in and out of the filter as centre poses.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from vlocbench.bench.localizer import LocalizationQuery, Localizer, PoseEstimate, planar_of
from vlocbench.bench.records import (
    EpisodeResult,
    LocalizationRecord,
    Reinitialization,
    Segment,
    Trajectory,
)
from vlocbench.config import config_hash, require, require_one_of
from vlocbench.geometry import planar_pose, pose_error, rpy_of, wrap_angle
from vlocbench.interfaces import Array, Control
from vlocbench.nav import (
    ControllerConfig,
    Ekf,
    EkfConfig,
    Failure,
    FailureConfig,
    FailureDetector,
    LocalPlanner,
    LocalPlannerConfig,
    OdometryNoise,
    OdometryReading,
    PoseMeasurement,
    ProgressConfig,
    ProgressTracker,
    VehicleController,
    WaypointPath,
    WheelOdometry,
)
from vlocbench.sim import Camera, Frame, StepResult, VehicleParams, VehicleState

# part of every episode key: bump when the same config gives a different result
# 3: the paper's navigation stack as the default (EKF, local planner, controller, collisions only),
#    time-outs count as failures, 6-DoF localization errors
# 4: a camera beyond its exposure range darkens through its gamma; CARLA's kind of night (a dark,
#    noiseless image) as the default camera
# 5: the paper's code as the default (issue 26): each (query keypoint, 3D point) one PnP
#    correspondence, the local planner's search over the whole route, time-outs not counted, the
#    car's 70 deg steering (the sun and the maps change keys through their own configs)
# 6: the town's lights at night (street lamps, lit windows); every light of a scene beyond the
#    camera's range scaled by its exposure share before the 8-bit quantization, not after
# 7: CARLA's wet world in the rain: puddles that mirror the scene, wet (darker, glossier) facades
# 8: the rain's streaks fitted on the paper's weather experiment (0.45 per 1000 pixels at rain 1)
# 9: the town's edge a wall (a lost car drove on past it over open ground, without a failure)
EPISODE_VERSION = 9


@dataclass(frozen=True)
class LatencyConfig:
    """When an answer reaches the EKF: ``none`` (at once), ``fixed`` (``fixed_s`` after its image;
    the default, deterministic) or ``measured`` (after the method's measured compute time, as on the
    paper's real-time system; not deterministic)."""

    mode: Literal["none", "fixed", "measured"] = "fixed"
    fixed_s: float = 0.2

    def __post_init__(self) -> None:
        require(self.fixed_s >= 0, "latency.fixed_s", "must be >= 0")


@dataclass(frozen=True)
class EpisodeConfig:
    mode: Literal["navigate", "ground_truth"] = "navigate"
    seed: int = 0
    localization_rate_hz: float = 2.0
    latency: LatencyConfig = field(default_factory=LatencyConfig)
    # give up after time_limit_factor * (route length / target speed) + 60 s of simulated time;
    # F divides by the route covered until then. timeout_is_failure (vlocbench's option): the
    # time-out is one failure more (cause "timeout"); the paper's harness counted none
    time_limit_factor: float = 3.0
    timeout_is_failure: bool = False
    # navigate mode: what the speed controller reads, the EKF's speed (the paper's local planner
    # reads the filtered odometry) or the car's true speed (vlocbench's option)
    speed_source: Literal["ekf", "speedometer"] = "ekf"
    record_trajectory: bool = True
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    local_planner: LocalPlannerConfig = field(default_factory=LocalPlannerConfig)
    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    ekf: EkfConfig = field(default_factory=EkfConfig)
    failure: FailureConfig = field(default_factory=FailureConfig)
    progress: ProgressConfig = field(default_factory=ProgressConfig)
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    # ground_truth drives: the EKF has lost lock once its position error stays above lock_lost_m
    # for lock_lost_s (a car navigating on it would be about to hit the kerb or parked cars)
    lock_lost_m: float = 3.0
    lock_lost_s: float = 1.0

    def __post_init__(self) -> None:
        require(self.lock_lost_m > 0, "lock_lost_m", "must be > 0")
        require(self.lock_lost_s >= 0, "lock_lost_s", "must be >= 0")
        require(
            0 < self.localization_rate_hz <= 20,
            "localization_rate_hz",
            f"must be in (0, 20] Hz, got {self.localization_rate_hz}",
        )
        require(self.time_limit_factor >= 1, "time_limit_factor", "must be >= 1")
        require_one_of(self.mode, ("navigate", "ground_truth"), "mode")
        require_one_of(self.speed_source, ("ekf", "speedometer"), "speed_source")


class EpisodeSimulator(Protocol):
    """What an episode asks of its simulator: a :class:`~vlocbench.sim.Simulator`, or a shared
    drive's stand-in for one (:mod:`vlocbench.bench.shared_drive`)."""

    @property
    def dt_s(self) -> float: ...

    @property
    def params(self) -> VehicleParams: ...

    @property
    def state(self) -> VehicleState: ...

    def set_vehicle(self, vehicle: VehicleParams) -> None: ...

    def reset(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState: ...

    def teleport(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState: ...

    def step(self, control: Control) -> StepResult: ...

    def render(self, cameras: Sequence[Camera]) -> list[Frame]: ...


@dataclass
class _InFlight:
    """A localization answer on its way to the EKF."""

    due_s: float
    time_s: float
    estimate: PoseEstimate
    truth: Array  # (4, 4) world_from_vehicle at the image time
    ekf: tuple[float, float, float]
    latency_s: float


class _Columns:
    """The trajectory's rows in the order of Trajectory's fields; a row's wheel odometry is the
    reading over the step that starts at its time (NaN until that step ran)."""

    def __init__(self) -> None:
        self.rows: list[list[float]] = []

    def add(
        self, t: float, s: VehicleState, ekf: tuple[float, float, float], ekf_cov: Array
    ) -> None:
        upper = ekf_cov[np.triu_indices(3)]
        self.rows.append([t, s.x_m, s.y_m, s.yaw_rad, *ekf, *upper, s.speed_mps, np.nan, np.nan])

    def odometry(self, reading: OdometryReading) -> None:
        if self.rows:
            self.rows[-1][-2:] = [reading.speed_mps, reading.yaw_rate_radps]

    def trajectory(self) -> Trajectory:
        names = [f.name for f in dataclasses.fields(Trajectory)]
        a = np.asarray(self.rows, dtype=np.float64).reshape(-1, len(names))
        return Trajectory(**{name: a[:, k].copy() for k, name in enumerate(names)})


def _record(p: _InFlight, fused: bool | None) -> LocalizationRecord:
    e = p.estimate
    tx, ty, tyaw = planar_of(p.truth)
    if e.success and e.world_from_vehicle is not None:
        x, y, yaw = planar_of(e.world_from_vehicle)
        z = float(e.world_from_vehicle[2, 3])
        roll, pitch, _ = rpy_of(e.world_from_vehicle[:3, :3])
        pos_err = float(np.hypot(x - tx, y - ty))
        yaw_err = float(np.degrees(np.abs(wrap_angle(yaw - tyaw))))
        pos_err_3d, rot_err = pose_error(p.truth, e.world_from_vehicle)
    else:
        x = y = z = yaw = roll = pitch = float("nan")
        pos_err = yaw_err = pos_err_3d = rot_err = float("nan")
    ex, ey, eyaw = p.ekf
    return LocalizationRecord(
        time_s=p.time_s,
        success=e.success,
        x_m=x,
        y_m=y,
        yaw_rad=yaw,
        z_m=z,
        roll_rad=roll,
        pitch_rad=pitch,
        true_x_m=tx,
        true_y_m=ty,
        true_yaw_rad=tyaw,
        ekf_x_m=ex,
        ekf_y_m=ey,
        ekf_yaw_rad=eyaw,
        position_error_m=pos_err,
        yaw_error_deg=yaw_err,
        position_error_3d_m=pos_err_3d,
        rotation_error_deg=rot_err,
        compute_time_s=e.compute_time_s,
        latency_s=p.latency_s,
        fused=fused,
        reason=e.reason,
        retrieval_distances_m=tuple(float(d) for d in e.retrieval_distances_m(p.truth)),
        retrieved_images=tuple(str(n) for n in e.retrieved),
        covariance=() if e.covariance is None else tuple(np.asarray(e.covariance, float).ravel()),
        inliers=int(e.inliers) if e.success else 0,
        stage_s={str(k): float(v) for k, v in e.stage_s.items()},
    )


class Episode:
    """One drive of ``path`` in ``sim`` (use :func:`run_episode`)."""

    def __init__(
        self,
        sim: EpisodeSimulator,
        path: WaypointPath,
        localizer: Localizer | None,
        config: EpisodeConfig,
    ) -> None:
        self.sim, self.path, self.localizer, self.config = sim, path, localizer, config
        sim.set_vehicle(config.vehicle)
        self.dt_s = sim.dt_s
        self.rear_offset_m = 0.5 * sim.params.wheelbase_m
        seeds = np.random.SeedSequence(config.seed).generate_state(2)
        self.odometry = WheelOdometry(config.odometry, seed=int(seeds[0]))
        if localizer is not None:
            localizer.reset(int(seeds[1]))
        self.ekf = Ekf(config.ekf)
        self.planner = LocalPlanner(path, config.local_planner, config.controller.target_speed_mps)
        self.controller = VehicleController(config.controller, self.dt_s)
        self.progress = ProgressTracker(path, config.progress)
        self.detector = FailureDetector(config.failure)
        self.in_flight: list[_InFlight] = []
        self.records: list[LocalizationRecord] = []
        self.reinits: list[Reinitialization] = []
        self.lock_losses_s: list[float] = []
        self.lock_lost_since_s: float | None = None
        self.segments: list[Segment] = []
        self.columns = _Columns()
        self.segment_start_s = 0.0
        self.next_query_s = 1.0 / config.localization_rate_hz
        self.distance_m = 0.0
        self.offsets_m: list[float] = []
        self.steps, self.t, self.limit_s, self.wall_s = 0, 0.0, 0.0, 0.0

    # -- frames: the EKF works on the rear axle, everything else on the car's centre ----------
    def _rear(self, x: float, y: float, yaw: float) -> tuple[float, float, float]:
        d = self.rear_offset_m
        return x - d * float(np.cos(yaw)), y - d * float(np.sin(yaw)), yaw

    def _ekf_pose(self) -> tuple[float, float, float]:
        x, y, yaw = self.ekf.pose
        d = self.rear_offset_m
        return x + d * float(np.cos(yaw)), y + d * float(np.sin(yaw)), yaw

    def _ekf_covariance(self) -> Array:
        """(3, 3) covariance of :meth:`_ekf_pose` (x, y, yaw): the filter's rear-axle pose
        moved forward by the rear offset, whose position then carries some of the yaw's
        uncertainty."""
        yaw, d = self.ekf.pose[2], self.rear_offset_m
        jac = np.array([[1, 0, -d * np.sin(yaw)], [0, 1, d * np.cos(yaw)], [0, 0, 1]])
        return jac @ self.ekf.P[:3, :3] @ jac.T

    # -- pieces of a step --------------------------------------------------------------------
    def _restart_at(self, index: int, t: float) -> None:
        x, y, yaw = (float(v) for v in (*self.path.xy[index], self.path.yaw_rad[index]))
        if t == 0.0:
            self.sim.reset(x, y, yaw)
        else:
            self.sim.teleport(x, y, yaw)
        self.ekf.reset(*self._rear(x, y, yaw), t)
        self.planner.reset(float(self.path.s_m[index]))
        self.controller.reset()
        self.detector.restart(t)
        for p in self.in_flight:  # answers about the car before it was moved are void
            self.records.append(_record(p, None))
        self.in_flight.clear()

    def _query(self, t: float, state: VehicleState) -> None:
        assert self.localizer is not None
        frames = tuple(self.sim.render(self.localizer.cameras)) if self.localizer.cameras else ()
        truth = state.world_from_vehicle()
        gt = truth if self.localizer.uses_ground_truth else None
        ekf_pose = self._ekf_pose()
        start = time.perf_counter()
        estimate = self.localizer.localize(LocalizationQuery(t, frames, planar_pose(*ekf_pose), gt))
        if estimate.compute_time_s == 0.0:
            estimate = dataclasses.replace(estimate, compute_time_s=time.perf_counter() - start)
        lat = self.config.latency
        latency = {"none": 0.0, "fixed": lat.fixed_s, "measured": estimate.compute_time_s}[lat.mode]
        due_s = t + latency
        self.in_flight.append(_InFlight(due_s, t, estimate, truth, ekf_pose, latency))
        period = 1.0 / self.config.localization_rate_hz
        # the next tick after this one at which the localizer is free again (its answer is out)
        while self.next_query_s <= t + 1e-9 or self.next_query_s < due_s - 1e-9:
            self.next_query_s += period

    def _deliver(self, t: float) -> None:
        due = [p for p in self.in_flight if p.due_s <= t + 1e-9]
        self.in_flight = [p for p in self.in_flight if p.due_s > t + 1e-9]
        for p in due:
            e = p.estimate
            fused = None
            if e.success and e.world_from_vehicle is not None:
                x, y, yaw = self._rear(*planar_of(e.world_from_vehicle))
                cov = self.config.ekf.pose_covariance() if e.covariance is None else e.covariance
                fused = self.ekf.update(PoseMeasurement(p.time_s, x, y, yaw, cov)).accepted
            self.records.append(_record(p, fused))

    def _odometry(self, before: VehicleState, after: VehicleState) -> OdometryReading:
        """A noisy reading of the rear axle's true motion over one step."""
        x0, y0, _ = self._rear(before.x_m, before.y_m, before.yaw_rad)
        x1, y1, _ = self._rear(after.x_m, after.y_m, after.yaw_rad)
        turned = float(wrap_angle(after.yaw_rad - before.yaw_rad))
        return self.odometry.read(float(np.hypot(x1 - x0, y1 - y0)) / self.dt_s, turned / self.dt_s)

    def _fail(self, failure: Failure, t: float) -> None:
        index = self.progress.farthest_index
        self.segments.append(Segment(self.segment_start_s, self.progress.farthest_s_m))
        self.reinits.append(
            Reinitialization(
                time_s=failure.time_s,
                x_m=failure.x_m,
                y_m=failure.y_m,
                cause=failure.cause,
                detail=failure.detail,
                resume_index=index,
                resume_s_m=float(self.path.s_m[index]),
            )
        )
        self.segment_start_s = float(self.path.s_m[index])
        self._restart_at(index, t)

    def _check_lock(self, t: float, state: VehicleState) -> None:
        """``ground_truth`` drives: reset the EKF at the true pose once it has lost lock."""
        x, y, _ = self._ekf_pose()
        if np.hypot(x - state.x_m, y - state.y_m) <= self.config.lock_lost_m:
            self.lock_lost_since_s = None
        elif self.lock_lost_since_s is None:
            self.lock_lost_since_s = t
        elif t - self.lock_lost_since_s >= self.config.lock_lost_s - 1e-9:
            self.ekf.reset(
                *self._rear(state.x_m, state.y_m, state.yaw_rad),
                t,
                state.speed_mps,
                state.yaw_rate_radps,
            )
            self.lock_losses_s.append(t)
            self.lock_lost_since_s = None

    # -- the loop: start, advance until it stops running, finish ------------------------------
    def run(self) -> EpisodeResult:
        self.start()
        while self.running:
            self.advance()
        return self.finish()

    def start(self) -> None:
        """Put the car at the route's start."""
        wall0 = time.perf_counter()
        c = self.config
        self.limit_s = c.time_limit_factor * self.path.length_m / c.controller.target_speed_mps
        self.limit_s += 60.0
        self.steps, self.t = 0, 0.0
        self._restart_at(0, 0.0)
        self.wall_s = time.perf_counter() - wall0

    @property
    def running(self) -> bool:
        """Until the goal, or out of time."""
        return not self.progress.finished and self.t < self.limit_s

    def advance(self) -> None:
        """One step of ``dt_s``."""
        wall0 = time.perf_counter()
        self.steps += 1
        self._step(self.t, self.steps * self.dt_s)
        self.t = self.steps * self.dt_s
        self.wall_s += time.perf_counter() - wall0

    def finish(self) -> EpisodeResult:
        """The result, once it stopped running; ``wall_time_s`` is this episode's own time in
        :meth:`start` and :meth:`advance` (episodes may advance in turns: see
        :mod:`vlocbench.bench.shared_drive`)."""
        return self._finish(self.t, self.wall_s)

    def _step(self, t: float, t_next: float) -> None:
        """One simulation step from ``t``: localize when due, steer, move, fuse the odometry,
        detect failures."""
        c = self.config
        state = self.sim.state
        if self.localizer is not None and t >= self.next_query_s - 1e-9:
            self._query(t, state)
        self._deliver(t)
        ekf_pose = self._ekf_pose()
        if c.record_trajectory:
            self.columns.add(t, state, ekf_pose, self._ekf_covariance())
        if c.mode == "navigate":
            x, y, yaw = ekf_pose
            speed = self.ekf.speed_mps if c.speed_source == "ekf" else state.speed_mps
        else:  # the paper's recall drive: on the true pose and speed
            x, y, yaw, speed = state.x_m, state.y_m, state.yaw_rad, state.speed_mps
        target = self.planner.step(np.array([x, y]), speed)
        cmd = self.controller.step(x, y, yaw, speed, target.xy, target.remaining_m)
        result = self.sim.step(cmd)
        new = result.state
        self.distance_m += float(np.hypot(new.x_m - state.x_m, new.y_m - state.y_m))
        reading = self._odometry(state, new)
        if c.record_trajectory:
            self.columns.odometry(reading)
        self.ekf.predict(reading, self.dt_s)
        proj = self.progress.update(np.array([new.x_m, new.y_m]))
        self.offsets_m.append(proj.distance_m)
        failure = next(
            (
                f
                for e in result.collisions
                if (f := self.detector.collision(t_next, e.x_m, e.y_m, f"{e.category} {e.label}"))
            ),
            None,
        ) or self.detector.check(t_next, new.x_m, new.y_m, new.speed_mps, proj.distance_m)
        if failure is not None and not self.progress.finished:
            self._fail(failure, t_next)
        if c.mode != "navigate":
            self._check_lock(t_next, new)

    def _finish(self, t: float, wall_s: float) -> EpisodeResult:
        """The episode's result once it ended at ``t`` (the goal, or out of time)."""
        c = self.config
        if c.record_trajectory:
            self.columns.add(t, self.sim.state, self._ekf_pose(), self._ekf_covariance())
        for p in self.in_flight:
            self.records.append(_record(p, None))
        self.segments.append(Segment(self.segment_start_s, self.progress.farthest_s_m))
        end = self.sim.state
        ex, ey, _ = self._ekf_pose()
        return EpisodeResult(
            episode_config_hash=config_hash(c),
            mode=c.mode,
            localizer="odometry" if self.localizer is None else self.localizer.name,
            route_length_m=self.path.length_m,
            route_covered_m=self.path.length_m
            if self.progress.finished
            else self.progress.farthest_s_m,
            distance_driven_m=self.distance_m,
            completed=self.progress.finished,
            timeout_is_failure=c.timeout_is_failure,
            sim_time_s=t,
            wall_time_s=wall_s,
            reinitializations=tuple(self.reinits),
            lock_losses_s=tuple(self.lock_losses_s),
            segments=tuple(self.segments),
            tracking_error_mean_m=float(np.mean(self.offsets_m)) if self.offsets_m else 0.0,
            final_drift_m=float(np.hypot(ex - end.x_m, ey - end.y_m)),
            localizations=tuple(self.records),
            trajectory=self.columns.trajectory(),
        )


def run_episode(
    sim: EpisodeSimulator,
    path: WaypointPath,
    localizer: Localizer | None = None,
    config: EpisodeConfig | None = None,
) -> EpisodeResult:
    """Drive ``path`` once; ``localizer=None`` is the wheel-odometry-only baseline.

    The simulator is reset first, so the result depends only on ``config`` (and the localizer).
    """
    return Episode(sim, path, localizer, config or EpisodeConfig()).run()
