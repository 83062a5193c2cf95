"""Stand-in episode runners for executor and store tests: instant, synthetic, picklable.

They run in worker processes (local pools start by spawn; Dask workers too), so they live in an
importable module and carry their behaviour in files named by the test, not in closures.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from vlocbench.bench.experiment import EpisodeTask
from vlocbench.bench.records import (
    EpisodeResult,
    LocalizationRecord,
    Reinitialization,
    Segment,
    Trajectory,
)
from vlocbench.bench.runner import EpisodeOutcome

CONTROL_ENV = "VLOCBENCH_TEST_FAKES"  # folder of marker files that steer the fakes


def synthetic_result(failures: int, queries: int = 4, lock_losses: int = 0) -> EpisodeResult:
    """A 100 m episode with ``failures`` re-initializations, ``queries`` localizations and
    ``lock_losses`` EKF resets."""
    n = 50
    t = np.linspace(0, 25, n)
    zero = np.zeros(n)
    trajectory = Trajectory(t, t * 4, zero, zero, t * 4 + 0.1, zero, zero, zero + 4)
    reinit = tuple(
        Reinitialization(5.0 * (k + 1), 20.0 * (k + 1), 0.0, "collision", "wall", k, 20.0 * (k + 1))
        for k in range(failures)
    )
    locs = tuple(
        LocalizationRecord(
            *(0.5 * k, True, 2.0 * k + 0.1, 0, 0, 2.0 * k, 0, 0, 2.0 * k, 0, 0),
            *(0.1, 0.5, 0.05, 0.2, True, ""),
        )
        for k in range(queries)
    )
    return EpisodeResult("fake", "navigate", "fake", 100.0, 100.0, True, 25.0, 0.01, reinit,
                         tuple(2.0 * (k + 1) for k in range(lock_losses)),
                         (Segment(0.0, 100.0),), 0.05, 0.1, locs, trajectory)  # fmt: skip


def _marker(task: EpisodeTask, what: str) -> Path | None:
    folder = os.environ.get(CONTROL_ENV)
    return (
        Path(folder) / f"{what}-{task.setup.label}-{task.method_name}-{task.repetition}"
        if folder
        else None
    )


def run_fake(task: EpisodeTask) -> EpisodeOutcome:
    """Instant episode; a worker dies (``os._exit``) on the first attempt of tasks with a ``die``
    marker, on every attempt with ``always-die``; ``sleep`` markers slow a task down."""
    die, always, slow = (_marker(task, w) for w in ("die", "always-die", "sleep"))
    if always is not None and always.exists():
        os._exit(3)
    if die is not None and die.exists():
        die.unlink()
        os._exit(3)
    if slow is not None and slow.exists():
        time.sleep(float(slow.read_text() or 1))
    failures = 3 if task.kind == "baseline" else task.repetition % 2
    return EpisodeOutcome(task.key, synthetic_result(failures), 0.01)
