"""The worker side of a run: what a process executes for a job (:func:`run_job`: one episode, or
the recall episodes of one setup on a shared drive), with the town's simulator and the last job's
localizers kept per process, so that consecutive episodes skip the scene build and the map load,
each outcome with the process's platform (:mod:`vlocbench.bench.platform`); and how a pool worker
starts (one thread each, ignoring Ctrl-C, stopping itself when its driver
dies)."""

from __future__ import annotations

import multiprocessing.context
import os
import signal
import threading
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from vlocbench.bench.episode import run_episode
from vlocbench.bench.experiment import EpisodeTask
from vlocbench.bench.localizer import Localizer
from vlocbench.bench.methods import MethodContext, build_localizer
from vlocbench.bench.platform import Platform, current_platform
from vlocbench.bench.records import EpisodeResult
from vlocbench.bench.shared_drive import can_share, run_shared_drive
from vlocbench.bench.towns import route_named, town_named
from vlocbench.config import config_hash
from vlocbench.sim import Simulator


@dataclass(frozen=True)
class EpisodeOutcome:
    """An episode's result, or the traceback of what it raised."""

    key: str
    result: EpisodeResult | None
    wall_s: float  # in the worker: its share of the town's and its map's loading included
    error: str | None = None
    platform: Platform | None = None  # where it ran (None: it never reached a worker)


Job = tuple[EpisodeTask, ...]  # episodes a worker runs together


def jobs_of(tasks: Sequence[EpisodeTask], share_drives: bool = True) -> list[Job]:
    """``tasks`` as jobs, in order: the recall episodes of several methods in one setup share a
    drive (:mod:`vlocbench.bench.shared_drive`) and make one job where the first of them was;
    every other episode is a job of its own."""
    jobs: dict[Any, list[EpisodeTask]] = {}
    for task in tasks:
        shared = share_drives and task.kind == "recall" and can_share(task.episode)
        group = (
            (
                task.town,
                task.route_length_m,
                config_hash((task.setup.conditions, task.setup.cameras, task.episode)),
            )
            if shared
            else task.key
        )
        jobs.setdefault(group, []).append(task)
    return [tuple(job) for job in jobs.values()]


_SIM: dict[tuple[str, Any], Simulator] = {}
_LOCALIZERS: dict[str, Localizer] = {}


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


def _localizer_key(task: EpisodeTask) -> str:
    return config_hash((task.method, task.map_dir, task.setup.cameras))


def _localizer(task: EpisodeTask) -> Localizer | None:
    """The job's localizer for ``task``, kept from the last job when method, map and rig match."""
    if task.method is None:
        return None
    key = _localizer_key(task)
    if key not in _LOCALIZERS:
        context = MethodContext(
            name=task.method.name,
            cameras=tuple(task.setup.cameras),
            town=task.town,
            map_dir=Path(task.map_dir) if task.map_dir else None,
            gallery_camera=task.gallery_camera,
        )
        _LOCALIZERS[key] = build_localizer(task.method, context)
    return _LOCALIZERS[key]


def _keep_localizers(job: Job) -> None:
    """Close the localizers the last job held that this one does not use."""
    keep = {_localizer_key(t) for t in job if t.method is not None}
    for key in [k for k in _LOCALIZERS if k not in keep]:
        _LOCALIZERS.pop(key).close()


def _run_task(task: EpisodeTask) -> EpisodeOutcome:
    """Run one episode in this process; what it raises propagates."""
    t = time.perf_counter()
    _keep_localizers((task,))
    localizer = _localizer(task)
    result = run_episode(
        _simulator(task), route_named(task.town, task.route_length_m), localizer, task.episode
    )
    return EpisodeOutcome(task.key, result, time.perf_counter() - t)


def worker_platform_id() -> str:
    """This process's platform id (what a cluster's workers are asked before a run)."""
    return current_platform().id


def run_job(job: Job) -> list[EpisodeOutcome]:
    """Run a job's episodes in this process (the function workers execute): each outcome holds
    its result or, where its episode raised, the traceback, and this process's platform."""
    try:
        platform = current_platform()  # once a process: not charged to an episode's wall time
    except Exception as exc:
        return [_failed(task, exc, 0.0) for task in job]
    if len(job) == 1:
        try:
            outcomes = [_run_task(job[0])]
        except Exception as exc:
            outcomes = [_failed(job[0], exc, 0.0)]
    else:
        outcomes = _run_shared(job)
    return [replace(o, platform=platform) for o in outcomes]


def _run_shared(job: Job) -> list[EpisodeOutcome]:
    """Recall episodes of one setup: those whose localizers ask for the same cameras share a
    drive."""
    t0 = time.perf_counter()
    _keep_localizers(job)
    first = job[0]
    sim = _simulator(first)
    path = route_named(first.town, first.route_length_m)
    setup_s = time.perf_counter() - t0  # the town's share, charged to the first drive's lead
    outcomes: dict[str, EpisodeOutcome] = {}
    drives: dict[tuple[Any, ...], list[tuple[EpisodeTask, Localizer, float]]] = {}
    for task in job:
        t = time.perf_counter()
        try:
            localizer = _localizer(task)
        except Exception as exc:
            outcomes[task.key] = _failed(task, exc, time.perf_counter() - t)
            continue
        assert localizer is not None  # recall episodes have a method
        built_s = time.perf_counter() - t
        drives.setdefault(tuple(localizer.cameras), []).append((task, localizer, built_s))
    for members in drives.values():
        results = run_shared_drive(sim, path, [loc for _, loc, _ in members], first.episode)
        for (task, _, built_s), result in zip(members, results):
            wall_s = built_s + setup_s
            setup_s = 0.0
            if isinstance(result, Exception):
                outcomes[task.key] = _failed(task, result, wall_s)
            else:
                outcomes[task.key] = EpisodeOutcome(task.key, result, wall_s + result.wall_time_s)
    return [outcomes[task.key] for task in job]


def _failed(task: EpisodeTask, exc: Exception, wall_s: float) -> EpisodeOutcome:
    return EpisodeOutcome(task.key, None, wall_s, "".join(traceback.format_exception(exc, limit=8)))


# a pool worker's thread pools: one thread each (OpenMP for torch, OpenBLAS for numpy, MKL, Mesa's
# llvmpipe renderer), since the pool already puts one worker on each core
WORKER_THREADS_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "LP_NUM_THREADS": "1",
}


class _WorkerProcess(multiprocessing.context.SpawnProcess):
    """A pool process that starts with :data:`WORKER_THREADS_ENV` in its environment: numpy's
    OpenBLAS reads it when numpy loads, before any initializer runs (unpickling the initializer
    loads it), and its threads spinning against the other workers' made a query's retrieval and
    matching 7x slower with 2 workers on 2 cores (``benchmarks/bench_runner.py``)."""

    def start(self) -> None:
        # the child copies the environment as it starts; the driver's own is restored at once
        saved = {k: os.environ.get(k) for k in WORKER_THREADS_ENV}
        os.environ.update(WORKER_THREADS_ENV)
        try:
            super().start()
        finally:
            for k, v in saved.items():
                if v is None:
                    del os.environ[k]
                else:
                    os.environ[k] = v


class WorkerContext(multiprocessing.context.SpawnContext):
    """The spawn start method, with each process's thread pools limited from its start."""

    Process = _WorkerProcess


def default_workers() -> int:
    """Local workers by default: one per core this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def worker_init(driver_pid: int) -> None:
    # OpenCV takes its threads from a call, not the environment (WorkerContext sets the others)
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
