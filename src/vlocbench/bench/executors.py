"""Executors: run episode tasks inline, on a local process pool or on a Dask cluster, and write
each outcome to the store as it arrives (the driver alone writes).

Tasks go to workers as jobs (:func:`~vlocbench.bench.worker.jobs_of`): one episode, or the recall
episodes of one setup that share a drive. At most one job per worker is in flight, so a worker
process that dies (a crash, the OOM killer) takes only its episodes with it: they are retried up to
``max_attempts`` times; an episode that raises is recorded with its error and the run goes on.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import os
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from vlocbench.bench.experiment import EpisodeTask
from vlocbench.bench.metrics import episode_metrics
from vlocbench.bench.progress import Progress
from vlocbench.bench.store import EpisodeRow, ResultStore
from vlocbench.bench.towns import town_named
from vlocbench.bench.worker import (
    EpisodeOutcome,
    Job,
    WorkerContext,
    jobs_of,
    run_job,
    worker_init,
    worker_platform_id,
)
from vlocbench.config import to_dict
from vlocbench.errors import ConfigError

CONNECT_TIMEOUT_S = 10  # to a Dask scheduler
logger = logging.getLogger(__name__)


@dataclass
class Tally:
    """What :func:`execute` did, counted as it goes: episodes finished, ended in an error, and run
    again after their worker died (by us, or by Dask on another worker); workers lost; seconds in
    episodes (summed over workers) and writing results; the most episodes at once."""

    finished: int = 0
    errors: int = 0
    retried: int = 0
    workers_lost: int = 0
    episode_s: float = 0.0
    store_s: float = 0.0
    slots: int = 1


def _row(task: EpisodeTask, outcome: EpisodeOutcome, attempts: int) -> EpisodeRow:
    config = {
        "kind": task.kind,
        "town": task.town,
        "setup": {
            "label": task.setup.label,
            "conditions": to_dict(task.setup.conditions),
            "cameras": to_dict(task.setup.cameras),
        },
        "method": to_dict(task.method) if task.method else None,
        "map_dir": task.map_dir,
        "episode": to_dict(task.episode),
        "key": task.key,
    }
    ok = outcome.result is not None
    return EpisodeRow(
        key=task.key,
        kind=task.kind,
        town=town_named(task.town).name,
        method=task.method_name,
        setup=task.setup.label,
        repetition=task.repetition,
        seed=task.episode.seed,
        config=config,
        status="ok" if ok else "error",
        error=outcome.error,
        metrics=episode_metrics(outcome.result) if outcome.result is not None else None,
        wall_s=outcome.wall_s if ok else None,
        attempts=attempts,
        platform=outcome.platform.id if outcome.platform else None,
    )


class Recorder:
    """Writes each episode's outcome to the store as it arrives, counts it, advances the bar."""

    def __init__(self, store: ResultStore, tally: Tally, total: int, progress: bool) -> None:
        self.store, self.tally = store, tally
        self.bar = Progress("episodes", total, "episode") if progress and total else None

    def job(self, job: Job, outcomes: list[EpisodeOutcome], attempts: int) -> None:
        """A job's outcomes: each episode's result or error."""
        for task, outcome in zip(job, outcomes, strict=True):
            self._write(task, outcome, attempts)

    def failed(self, job: Job, error: str, attempts: int) -> None:
        """A job that ended without outcomes: the error for each of its episodes."""
        for task in job:
            self._write(task, EpisodeOutcome(task.key, None, 0.0, error), attempts)

    def _write(self, task: EpisodeTask, outcome: EpisodeOutcome, attempts: int) -> None:
        t = time.perf_counter()
        self.store.write_episode(_row(task, outcome, attempts), outcome.result, outcome.platform)
        self.tally.store_s += time.perf_counter() - t
        if outcome.result is not None:
            self.tally.finished += 1
            self.tally.episode_s += outcome.wall_s
        else:
            self.tally.errors += 1
        if self.bar is not None:
            done = self.tally.finished + self.tally.errors
            self.bar.update_to(
                done,
                f"ok {self.tally.finished} err {self.tally.errors} | {task.town} "
                f"{task.method_name} {task.kind}",
            )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


Runner = Callable[[Job], list[EpisodeOutcome]]


def execute(
    tasks: list[EpisodeTask],
    store: ResultStore,
    workers: int = 1,
    scheduler: str | None = None,
    runner: Runner = run_job,
    max_attempts: int = 3,
    progress: bool = True,
    share_drives: bool = True,
) -> Tally:
    """Run ``tasks``, writing each outcome as it arrives.

    The tasks run as jobs (:func:`~vlocbench.bench.worker.jobs_of`; ``share_drives=False``: one
    episode each). ``workers == 1`` without a scheduler runs in this process. Otherwise at most one
    job per worker is in flight, so a worker that dies takes only the episodes in flight with it:
    they are run again (up to ``max_attempts`` in all) on a fresh pool; Dask reschedules them
    itself. An interruption (Ctrl-C, SIGTERM, a store error) stops every worker of a local pool
    before it propagates; what was stored stays stored.
    """
    check_workers(workers)
    tally = Tally(slots=workers)
    record = Recorder(store, tally, len(tasks), progress)
    jobs = jobs_of(tasks, share_drives)
    try:
        if scheduler is not None:
            _run_on_dask(jobs, scheduler, runner, record, tally)
        elif workers == 1:
            _run_inline(jobs, runner, record)
        else:
            _run_on_pool(jobs, workers, runner, record, tally, max_attempts)
    finally:
        record.close()
    return tally


def _run_inline(jobs: list[Job], runner: Runner, record: Recorder) -> None:
    for job in jobs:
        try:
            outcomes = runner(job)
        except Exception:  # an episode's bug must not end the run: record it
            record.failed(job, traceback.format_exc(limit=8), 1)
            continue
        record.job(job, outcomes, 1)


def local_pool(workers: int) -> cf.ProcessPoolExecutor:
    return cf.ProcessPoolExecutor(
        workers,
        mp_context=WorkerContext(),
        initializer=worker_init,
        initargs=(os.getpid(),),
    )


@contextmanager
def worker_pool(workers: int) -> Iterator[cf.ProcessPoolExecutor]:
    """``workers`` pool processes (one thread each) for the ``with`` block; a failure or an
    interruption in it kills them rather than waiting for their jobs."""
    pool = local_pool(workers)
    try:
        yield pool
    except BaseException:
        kill_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _run_on_pool(
    jobs: list[Job],
    workers: int,
    runner: Runner,
    record: Recorder,
    tally: Tally,
    max_attempts: int,
) -> None:
    """Local worker processes; a pool broken by a dead worker is replaced, and the jobs that
    were in flight in it run again."""
    attempts = dict.fromkeys((job[0].key for job in jobs), 0)
    pending = deque(jobs)
    while pending:
        lost = _pool_round(pending, workers, runner, record, attempts)
        if lost:
            tally.workers_lost += 1
        for job in lost:
            if attempts[job[0].key] < max_attempts:
                pending.appendleft(job)
                tally.retried += len(job)
            else:
                record.failed(job, "its worker process died", attempts[job[0].key])


def _pool_round(
    pending: deque[Job],
    workers: int,
    runner: Runner,
    record: Recorder,
    attempts: dict[str, int],
) -> list[Job]:
    """Run ``pending`` on one pool until it is empty or the pool breaks; returns the jobs that
    were in flight when it broke."""
    pool = local_pool(workers)
    running: dict[cf.Future, Job] = {}
    lost: list[Job] = []
    try:
        while (pending or running) and not lost:
            while pending and len(running) < workers:
                job = pending.popleft()
                attempts[job[0].key] += 1
                running[pool.submit(runner, job)] = job
            done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for future in done:
                job = running.pop(future)
                n = attempts[job[0].key]
                try:
                    outcomes = future.result()
                except cf.process.BrokenProcessPool:
                    lost.append(job)
                    continue
                except Exception as exc:
                    record.failed(job, _describe(exc), n)
                    continue
                record.job(job, outcomes, n)
        # a broken pool: everything still in flight died with it
        return [*lost, *running.values()] if lost else []
    finally:
        if running or lost:  # interrupted or broken: don't wait for workers
            kill_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)


def kill_workers(pool: cf.ProcessPoolExecutor) -> None:
    # the executor has no public way to stop workers in the middle of an episode
    for process in list(getattr(pool, "_processes", {}).values()):
        process.kill()


def _run_on_dask(
    jobs: list[Job],
    scheduler: str,
    runner: Runner,
    record: Recorder,
    tally: Tally,
    poll_s: float = 1.0,
) -> None:
    """A Dask cluster: twice as many jobs in flight as it has threads, so that its workers stay
    fed. Dask reruns the jobs of a worker that dies (giving up with ``KilledWorker``); the
    scheduler's count of jobs caught in a worker's death and the workers that vanished go into
    the tally."""
    client = _dask_client(scheduler)
    try:
        _check_dask_platforms(client)
        tally.slots = sum(client.nthreads().values()) or 1
        window = 2 * tally.slots
        pending = deque(jobs)
        running: dict[Any, Job] = {}
        seen = set(client.scheduler_info()["workers"])
        prefix, suspicious_before = None, 0
        while pending or running:
            while pending and len(running) < window:
                job = pending.popleft()
                future = client.submit(runner, job, pure=False)
                running[future] = job
                if prefix is None:
                    from dask.utils import key_split

                    prefix = key_split(future.key)
                    suspicious_before = _dask_suspicious(client, prefix)
            done = _dask_wait(list(running), poll_s)
            now = set(client.scheduler_info()["workers"])
            tally.workers_lost += len(seen - now)
            seen = now
            if done and prefix is not None:  # before the results are released
                tally.retried = _dask_suspicious(client, prefix) - suspicious_before
            for future in done:
                job = running.pop(future)
                try:
                    outcomes = future.result()
                except Exception as exc:
                    record.failed(job, _describe(exc), 1)
                    continue
                record.job(job, outcomes, 1)
        for future in running:
            future.cancel()
    finally:
        client.close()


def _check_dask_platforms(client: Any) -> None:
    """Warn, before any episode, when the cluster's workers are on several platforms: each
    renders and rounds as its machine does, so a store they fill together mixes them (every
    worker computes its record now, once, as its first episode would)."""
    workers: dict[str, list[str]] = {}
    for address, platform_id in client.run(worker_platform_id).items():
        workers.setdefault(platform_id, []).append(address)
    if len(workers) > 1:
        on = "; ".join(f"{p}: {', '.join(sorted(a))}" for p, a in sorted(workers.items()))
        logger.warning(
            f"the Dask cluster's workers are on {len(workers)} platforms ({on}): they render or "
            "compute the same scene differently, so one config and seed need not give the same "
            "numbers on each (`vlocbench platform` on each machine says how they differ)"
        )


def _dask_wait(futures: list[Any], timeout_s: float) -> list[Any]:
    from distributed import wait

    try:
        done, _ = wait(futures, timeout=timeout_s, return_when="FIRST_COMPLETED")
    except TimeoutError:
        return []
    return list(done)


def _dask_suspicious(client: Any, prefix: str) -> int:
    """How many times the scheduler saw tasks of ``prefix`` on a worker that died."""

    def count(dask_scheduler: Any) -> int:
        tp = dask_scheduler.task_prefixes.get(prefix)
        return 0 if tp is None else int(tp.suspicious)

    return int(client.run_on_scheduler(count))


def check_workers(workers: int) -> None:
    if workers < 1:
        raise ConfigError("--workers", f"must be >= 1, got {workers}")


def _describe(exc: BaseException) -> str:
    if type(exc).__name__ == "KilledWorker":  # Dask gave up after its own retries
        return f"its worker died on every attempt ({exc})"
    return "".join(traceback.format_exception(exc, limit=8))


def _dask_client(scheduler: str) -> Any:
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError(
            "--scheduler", "Dask is not installed: pip install 'vlocbench[dask]'"
        ) from None
    try:
        return Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
    except OSError as exc:
        raise ConfigError("--scheduler", f"cannot reach {scheduler}: {exc}") from None
