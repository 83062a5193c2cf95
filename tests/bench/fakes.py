"""Stand-in episode runners for executor and store tests: instant, synthetic, picklable.

They run in worker processes (local pools start by spawn; Dask workers too), so they live in an
importable module and carry their behaviour in files named by the test, not in closures.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from vlocbench.bench.executors import execute
from vlocbench.bench.experiment import EpisodeTask, load_experiment
from vlocbench.bench.records import (
    EpisodeResult,
    LocalizationRecord,
    Reinitialization,
    Segment,
    Trajectory,
)
from vlocbench.bench.store import ResultStore, run_hash
from vlocbench.bench.worker import EpisodeOutcome, Job
from vlocbench.config import to_dict

CONTROL_ENV = "VLOCBENCH_TEST_FAKES"  # folder of marker files that steer the fakes


def synthetic_result(failures: int, queries: int = 4, lock_losses: int = 0) -> EpisodeResult:
    """A 100 m episode with ``failures`` re-initializations, ``queries`` localizations and
    ``lock_losses`` EKF resets."""
    n = 50
    t = np.linspace(0, 25, n)
    zero = np.zeros(n)
    trajectory = Trajectory(
        time_s=t,
        true_x_m=t * 4,
        true_y_m=zero,
        true_yaw_rad=zero,
        ekf_x_m=t * 4 + 0.1,
        ekf_y_m=zero,
        ekf_yaw_rad=zero,
        ekf_cov_xx_m2=zero + 0.01,
        ekf_cov_xy_m2=zero,
        ekf_cov_xyaw_mrad=zero,
        ekf_cov_yy_m2=zero + 0.01,
        ekf_cov_yyaw_mrad=zero,
        ekf_cov_yawyaw_rad2=zero + 1e-4,
        speed_mps=zero + 4,
        odometry_speed_mps=zero + 4.1,
        odometry_yaw_rate_radps=zero + 0.01,
    )
    reinit = tuple(
        Reinitialization(
            time_s=5.0 * (k + 1),
            x_m=20.0 * (k + 1),
            y_m=0.0,
            cause="collision",
            detail="wall",
            resume_index=k,
            resume_s_m=20.0 * (k + 1),
        )
        for k in range(failures)
    )
    locs = tuple(
        LocalizationRecord(
            time_s=0.5 * k,
            success=True,
            x_m=2.0 * k + 0.1,
            y_m=0.0,
            yaw_rad=0.0,
            z_m=0.0,
            roll_rad=0.0,
            pitch_rad=0.0,
            true_x_m=2.0 * k,
            true_y_m=0.0,
            true_yaw_rad=0.0,
            ekf_x_m=2.0 * k,
            ekf_y_m=0.0,
            ekf_yaw_rad=0.0,
            position_error_m=0.1,
            yaw_error_deg=0.5,
            position_error_3d_m=0.1,
            rotation_error_deg=0.5,
            compute_time_s=0.05,
            latency_s=0.2,
            fused=True,
            reason="",
            stage_s={"features": 0.03, "pnp": 0.02} if k % 2 == 0 else {},
        )
        for k in range(queries)
    )
    return EpisodeResult(
        episode_config_hash="fake",
        mode="navigate",
        localizer="fake",
        route_length_m=100.0,
        route_covered_m=100.0,
        distance_driven_m=100.0,
        completed=True,
        sim_time_s=25.0,
        wall_time_s=0.01,
        reinitializations=reinit,
        lock_losses_s=tuple(2.0 * (k + 1) for k in range(lock_losses)),
        segments=(Segment(0.0, 100.0),),
        tracking_error_mean_m=0.05,
        final_drift_m=0.1,
        localizations=locs,
        trajectory=trajectory,
    )


def _marker(task: EpisodeTask, what: str) -> Path | None:
    folder = os.environ.get(CONTROL_ENV)
    return (
        Path(folder) / f"{what}-{task.setup.label}-{task.method_name}-{task.repetition}"
        if folder
        else None
    )


def run_fake(job: Job) -> list[EpisodeOutcome]:
    """Instant episodes (see :func:`fake_episode`), one after another."""
    return [fake_episode(task) for task in job]


def fake_episode(task: EpisodeTask) -> EpisodeOutcome:
    """Instant episode; a worker dies (``os._exit``) on the first attempt of tasks with a ``die``
    marker, on every attempt with ``always-die``; ``sleep`` markers slow a task down (``sleep-all``
    every task)."""
    die, always, slow = (_marker(task, w) for w in ("die", "always-die", "sleep"))
    if slow is not None and not slow.exists():
        slow = slow.with_name("sleep-all")
    if always is not None and always.exists():
        os._exit(3)
    if die is not None and die.exists():
        die.unlink()
        os._exit(3)
    if slow is not None and slow.exists():
        time.sleep(float(slow.read_text() or 1))
    failures = 3 if task.kind == "baseline" else task.repetition % 2
    return EpisodeOutcome(task.key, synthetic_result(failures), 0.01)


def fake_tasks():
    spec = load_experiment(
        {
            "name": "fake",
            "towns": ["town10"],
            "methods": ["sift"],
            "sweep": {"illumination.k": [0, 6]},
            "repetitions": 2,
        }
    )
    return spec.tasks()  # 2 x (1 + 2) + 10 = 16


def fake_maps(plan):
    """Map folders named as the runner names them (none is built: the fake episodes need none)."""
    return {
        (t, m.name): f"/nowhere/{plan.gallery_folder(t)}-0123456789/{plan.map_name(m)}"
        for t in plan.spec.towns
        for m in plan.spec.methods
    }


def run_fake_plans(root, *plans):
    """Run ``plans`` in turn into the store at ``root`` as the runner would."""
    with ResultStore(root, "ill") as store:
        for plan in plans:
            tasks = [t.on_maps(fake_maps(plan)) for t in plan.tasks()]
            store.start_run(run_hash(t.key for t in tasks), to_dict(plan), [t.key for t in tasks])
            todo = [t for t in tasks if t.key not in store.done_keys()]
            execute(todo, store, workers=1, runner=run_fake, progress=False)


ILL_SPEC = {
    "name": "ill",
    "towns": ["town10"],
    "methods": ["sift"],
    "repetitions": 1,
    "baseline_repetitions": 1,
}
