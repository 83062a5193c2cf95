"""The worker side of a run: what a process executes for one episode (:func:`run_task`), with the
town's simulator and the last localizer kept per process, so that consecutive episodes skip the
scene build and the map load; and how a pool worker starts (one thread each, ignoring Ctrl-C,
stopping itself when its driver dies)."""

from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlocbench.bench.episode import run_episode
from vlocbench.bench.experiment import EpisodeTask
from vlocbench.bench.localizer import Localizer
from vlocbench.bench.methods import MethodContext, build_localizer
from vlocbench.bench.records import EpisodeResult
from vlocbench.bench.towns import route_named, town_named
from vlocbench.config import config_hash
from vlocbench.sim import Simulator


@dataclass(frozen=True)
class EpisodeOutcome:
    key: str
    result: EpisodeResult
    wall_s: float  # in the worker, town and map loading included


_SIM: dict[tuple[str, Any], Simulator] = {}
_LOCALIZER: dict[str, Localizer] = {}


def _simulator(task: EpisodeTask) -> Simulator:
    """One simulator per town and traffic slot count in this process; conditions are switched."""
    key = (task.town, task.setup.conditions.traffic)
    sim = _SIM.get(key)
    if sim is None:
        for old in list(_SIM):
            if old[0] == task.town:  # keep one scene per town in memory
                _SIM.pop(old).close()
        sim = _SIM[key] = Simulator(town_named(task.town), task.setup.conditions)
    else:
        sim.set_conditions(task.setup.conditions)
    return sim


def _localizer(task: EpisodeTask) -> Localizer | None:
    """The last localizer of this process, rebuilt only when method, map or rig change."""
    if task.method is None:
        return None
    key = config_hash((task.method, task.map_dir, task.setup.cameras))
    if key not in _LOCALIZER:
        for old in _LOCALIZER.values():
            old.close()
        _LOCALIZER.clear()
        context = MethodContext(
            name=task.method.name,
            cameras=tuple(task.setup.cameras),
            town=task.town,
            map_dir=Path(task.map_dir) if task.map_dir else None,
        )
        _LOCALIZER[key] = build_localizer(task.method, context)
    return _LOCALIZER[key]


def run_task(task: EpisodeTask) -> EpisodeOutcome:
    """Run one episode in this process (the function workers execute)."""
    t = time.perf_counter()
    localizer = _localizer(task)
    result = run_episode(
        _simulator(task), route_named(task.town, task.route_length_m), localizer, task.episode
    )
    return EpisodeOutcome(task.key, result, time.perf_counter() - t)


# a pool worker's thread pools: one thread each (OpenMP for torch, MKL, Mesa's llvmpipe renderer),
# since the pool already puts one worker on each core
WORKER_THREADS_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "LP_NUM_THREADS": "1"}


def default_workers() -> int:
    """Local workers by default: one per core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def worker_init(driver_pid: int) -> None:
    # threads of a worker spinning against the other workers' make every one crawl; set before
    # torch and the renderer start (with the first episode), which read them then
    os.environ.update(WORKER_THREADS_ENV)
    import cv2

    cv2.setNumThreads(1)
    # Ctrl-C reaches the whole process group: the driver alone handles it (it stops the workers)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_driver, args=(driver_pid,), daemon=True).start()


def _exit_with_driver(driver_pid: int, period_s: float = 1.0) -> None:
    """A pool worker's watchdog: a driver killed outright (``kill -9``) cannot stop its workers,
    so each stops itself once it is no longer the driver's child (also when the driver died
    while the worker was still starting)."""
    while os.getppid() == driver_pid:
        time.sleep(period_s)
    os._exit(1)
