"""Running an experiment: galleries and maps (built once, reused), then every episode not yet in
the store, on a local process pool or a Dask cluster; the driver alone writes the store.

Workers get an :class:`EpisodeTask` and return an :class:`EpisodeOutcome`; they keep a town, a
simulator and the last localizer per process, so consecutive episodes skip the scene build and the
map load. A worker process that dies (a crash, the OOM killer) has its episode retried up to
``max_attempts`` times; an episode that raises is recorded with its error and the run goes on.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
import multiprocessing
import os
import signal
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from vlocbench.bench.episode import run_episode
from vlocbench.bench.experiment import EpisodeTask, ExperimentPlan
from vlocbench.bench.gallery_capture import capture_gallery
from vlocbench.bench.localizer import Localizer
from vlocbench.bench.methods import MethodContext, MethodSpec, build_localizer, check_methods
from vlocbench.bench.metrics import episode_metrics
from vlocbench.bench.records import EpisodeResult
from vlocbench.bench.store import EpisodeRow, ResultStore, StoreError
from vlocbench.bench.towns import route_named, town_named
from vlocbench.config import config_hash, to_dict
from vlocbench.errors import ConfigError
from vlocbench.loc.gallery import GALLERY_FILE, Gallery
from vlocbench.loc.mapping import MAP_FILE, MappingConfig, build_map, default_map_dir
from vlocbench.locks import building
from vlocbench.sim import Simulator

logger = logging.getLogger(__name__)
CONNECT_TIMEOUT_S = 10  # to a Dask scheduler


@dataclass(frozen=True)
class EpisodeOutcome:
    key: str
    result: EpisodeResult
    wall_s: float  # in the worker, town and map loading included


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


@dataclass(frozen=True, kw_only=True)
class RunSummary:
    output_dir: Path
    total: int
    skipped: int  # finished in an earlier run
    finished: int
    errors: int
    retried: int  # episodes rerun after their worker died
    workers_lost: int  # worker processes that died during the run
    wall_s: float  # the whole run, galleries and maps included
    episodes_wall_s: float  # the episode phase
    episode_s: float  # the sum of the episodes' times in their workers
    store_s: float  # the driver's time writing results (metrics, Parquet, SQLite)
    slots: int  # episodes that could run at once: local workers, or the Dask cluster's threads

    @property
    def harness_overhead(self) -> float | None:
        """Episode-phase time beyond the workers' episode time, as a fraction of the latter
        (storing, scheduling, transfers, idle workers at the end); None when a worker died, as the
        work lost with it and the smaller pool after it make the figure meaningless."""
        busy = self.episode_s / self.slots
        if self.workers_lost:
            return None
        return 0.0 if busy <= 0 else max(0.0, self.episodes_wall_s / busy - 1)

    @property
    def store_overhead(self) -> float:
        """The driver's writing time as a fraction of the episodes' time."""
        return 0.0 if self.episode_s <= 0 else self.store_s / self.episode_s


# -- the worker side ------------------------------------------------------------------------------
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


def _worker_init(driver_pid: int) -> None:
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


# -- the driver side ------------------------------------------------------------------------------
class _StageBars:
    """One tqdm bar per preparation stage (gallery images, features, matches), updated by the
    stages' progress callbacks; nothing when disabled."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bars: dict[str, Any] = {}

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage not in self.bars:
            from tqdm import tqdm

            self.bars[stage] = tqdm(total=total, desc=stage, unit="image", dynamic_ncols=True)
        bar = self.bars[stage]
        bar.update(done - bar.n)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def prepare_maps(
    plan: ExperimentPlan, progress: bool = False, workers: int = 1
) -> dict[tuple[str, str], str]:
    """Capture each town's gallery and build each method's map, unless the cache has them; returns
    the map folders by (town, method name). With ``workers`` > 1 the galleries, then the maps, are
    made side by side in as many processes (a gallery and a map build each use about one core)."""
    spec = plan.spec
    cache = Path(spec.cache).resolve()
    if not (spec.recall or spec.failure) or not any(m.needs_map for m in spec.methods):
        return {}  # no map to localize against, so no gallery either
    bars = _StageBars(progress)
    try:
        if workers > 1:
            todo = [
                t for t in spec.towns if not (_gallery_dir(plan, t, cache) / GALLERY_FILE).exists()
            ]
            _in_parallel(_gallery_job, [(plan, t, cache) for t in todo], workers, bars, "galleries")
        galleries = {t: _gallery(plan, t, cache, bars) for t in spec.towns}
        jobs = {}  # (town, method name) -> what _map builds it from
        for town in spec.towns:
            for method in (m for m in spec.methods if m.needs_map):
                mapping = method.mapping or spec.mapping
                map_dir = default_map_dir(cache / "maps", galleries[town], method.name,
                                          method.conf, mapping)  # fmt: skip
                jobs[(town, method.name)] = (town, galleries[town], method, mapping, map_dir)
        if workers > 1:
            todo = [j for j in jobs.values() if not (j[-1] / MAP_FILE).exists()]
            _in_parallel(_map_job, todo, workers, bars, "maps")
        return {key: str(_map(*job, bars)) for key, job in jobs.items()}
    finally:
        bars.close()


def prepare_gallery(plan: ExperimentPlan, town_name: str, progress: bool = False) -> Gallery:
    """The gallery of ``town_name`` as the experiment captures it, captured unless cached."""
    bars = _StageBars(progress)
    try:
        return _gallery(plan, town_name, Path(plan.spec.cache).resolve(), bars)
    finally:
        bars.close()


def _in_parallel(job: Callable[..., object], args: list[tuple[Any, ...]], workers: int,
                 bars: _StageBars, stage: str) -> None:  # fmt: skip
    """``job(*a)`` for every ``a`` of ``args`` on a pool of pool workers (one thread each); a
    failure or an interruption stops the others. The jobs' own progress is not shown: one bar
    counts the jobs."""
    if len(args) < 2:
        return  # one job runs in the driver, with every thread
    logger.info(f"{len(args)} {stage} to make, {min(workers, len(args))} at a time")
    pool = _local_pool(min(workers, len(args)))
    try:
        futures = [pool.submit(job, *a) for a in args]
        for n, future in enumerate(cf.as_completed(futures), 1):
            future.result()
            bars(stage, n, len(args))
    except BaseException:
        _kill_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _gallery_job(plan: ExperimentPlan, town_name: str, cache: Path) -> None:
    _gallery(plan, town_name, cache, _StageBars(False))


def _map_job(town_name: str, gallery: Gallery, method: MethodSpec, mapping: MappingConfig,
             map_dir: Path) -> None:  # fmt: skip
    _map(town_name, gallery, method, mapping, map_dir, _StageBars(False))


def _gallery_dir(plan: ExperimentPlan, town_name: str, cache: Path) -> Path:
    return cache / "galleries" / plan.gallery_folder(town_name)


def _gallery(plan: ExperimentPlan, town_name: str, cache: Path, bars: _StageBars) -> Gallery:
    spec, town = plan.spec, town_named(town_name)
    gallery_dir = _gallery_dir(plan, town_name, cache)
    with building(gallery_dir, "a gallery"):
        if not (gallery_dir / GALLERY_FILE).exists():
            logger.info(f"{town.name}: capturing the gallery in {gallery_dir}")
            t = time.perf_counter()
            route = route_named(town_name, spec.route_length_m)
            shots = int(route.length_m / spec.gallery.spacing_m) + 1
            with Simulator(town, spec.gallery.conditions) as sim:
                capture_gallery(sim, route, (spec.gallery.camera,), gallery_dir,
                                spec.gallery.spacing_m, spec.gallery.speed_mps,
                                progress=lambda n: bars(f"{town.name} gallery", n, shots))  # fmt: skip
            logger.info(f"{town.name}: gallery captured in {time.perf_counter() - t:.0f} s")
    return Gallery.load(gallery_dir)


def _map(town_name: str, gallery: Gallery, method: MethodSpec, mapping: MappingConfig,
         map_dir: Path, bars: _StageBars) -> Path:  # fmt: skip
    """The map of ``method`` on the town's ``gallery`` in ``map_dir``, built unless it is there."""
    name = town_named(town_name).name
    if not (map_dir / MAP_FILE).exists():
        logger.info(f"{name}: building the {method.name} map in {map_dir}")
    label = f"{name} {method.name}"
    report = build_map(gallery, method.conf, map_dir, mapping,
                       progress=lambda stage, done, total: bars(f"{label} {stage}", done, total))  # fmt: skip
    logger.info(f"{name}: {method.name} map: {report.images} images, {report.points} points")
    return map_dir


def _row(task: EpisodeTask, outcome: EpisodeOutcome | None, error: str | None,
         attempts: int) -> EpisodeRow:  # fmt: skip
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
    metrics = asdict(episode_metrics(outcome.result)) if outcome else None
    return EpisodeRow(
        key=task.key,
        kind=task.kind,
        town=town_named(task.town).name,
        method=task.method_name,
        setup=task.setup.label,
        repetition=task.repetition,
        seed=task.episode.seed,
        config=config,
        status="ok" if outcome else "error",
        error=error,
        metrics=metrics,
        wall_s=outcome.wall_s if outcome else None,
        attempts=attempts,
    )


class _Recorder:
    """Writes each episode's outcome to the store as it arrives, counts it, advances the bar."""

    def __init__(self, store: ResultStore, tally: Tally, total: int, progress: bool) -> None:
        self.store, self.tally = store, tally
        self.bar = None
        if progress and total:
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="episode", dynamic_ncols=True)

    def __call__(self, task: EpisodeTask, outcome: EpisodeOutcome | None, error: str | None,
                 attempts: int) -> None:  # fmt: skip
        t = time.perf_counter()
        self.store.write_episode(_row(task, outcome, error, attempts),
                                 outcome.result if outcome else None)  # fmt: skip
        self.tally.store_s += time.perf_counter() - t
        if outcome:
            self.tally.finished += 1
            self.tally.episode_s += outcome.wall_s
        else:
            self.tally.errors += 1
        if self.bar is not None:
            self.bar.set_postfix_str(
                f"ok {self.tally.finished} err {self.tally.errors} | {task.town} "
                f"{task.method_name} {task.kind}",
                refresh=False,
            )
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


Runner = Callable[[EpisodeTask], EpisodeOutcome]


def execute(
    tasks: list[EpisodeTask],
    store: ResultStore,
    workers: int = 1,
    scheduler: str | None = None,
    runner: Runner = run_task,
    max_attempts: int = 3,
    progress: bool = True,
) -> Tally:
    """Run ``tasks``, writing each outcome as it arrives.

    ``workers == 1`` without a scheduler runs in this process. Otherwise at most one episode per
    worker is in flight, so a worker that dies takes only the episodes in flight with it: they are
    run again (up to ``max_attempts`` in all) on a fresh pool; Dask reschedules them itself. An
    interruption (Ctrl-C, SIGTERM, a store error) stops every worker of a local pool before it
    propagates; what was stored stays stored.
    """
    _check_workers(workers)
    tally = Tally(slots=workers)
    record = _Recorder(store, tally, len(tasks), progress)
    try:
        if scheduler is not None:
            _run_on_dask(tasks, scheduler, runner, record, tally)
        elif workers == 1:
            _run_inline(tasks, runner, record)
        else:
            _run_on_pool(tasks, workers, runner, record, tally, max_attempts)
    finally:
        record.close()
    return tally


def _run_inline(tasks: list[EpisodeTask], runner: Runner, record: _Recorder) -> None:
    for task in tasks:
        try:
            outcome = runner(task)
        except Exception:  # an episode's bug must not end the run: record it
            record(task, None, traceback.format_exc(limit=8), 1)
            continue
        record(task, outcome, None, 1)


def _local_pool(workers: int) -> cf.ProcessPoolExecutor:
    return cf.ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_worker_init,
        initargs=(os.getpid(),),
    )


def _run_on_pool(tasks: list[EpisodeTask], workers: int, runner: Runner, record: _Recorder,
                 tally: Tally, max_attempts: int) -> None:  # fmt: skip
    """Local worker processes; a pool broken by a dead worker is replaced, and the episodes that
    were in flight in it run again."""
    attempts = dict.fromkeys((t.key for t in tasks), 0)
    pending = deque(tasks)
    while pending:
        lost = _pool_round(pending, workers, runner, record, attempts)
        if lost:
            tally.workers_lost += 1
        for task in lost:
            if attempts[task.key] < max_attempts:
                pending.appendleft(task)
                tally.retried += 1
            else:
                record(task, None, "its worker process died", attempts[task.key])


def _pool_round(pending: deque[EpisodeTask], workers: int, runner: Runner, record: _Recorder,
                attempts: dict[str, int]) -> list[EpisodeTask]:  # fmt: skip
    """Run ``pending`` on one pool until it is empty or the pool breaks; returns the episodes
    that were in flight when it broke."""
    pool = _local_pool(workers)
    running: dict[cf.Future, EpisodeTask] = {}
    lost: list[EpisodeTask] = []
    try:
        while (pending or running) and not lost:
            while pending and len(running) < workers:
                task = pending.popleft()
                attempts[task.key] += 1
                running[pool.submit(runner, task)] = task
            done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for future in done:
                task = running.pop(future)
                try:
                    outcome = future.result()
                except cf.process.BrokenProcessPool:
                    lost.append(task)
                    continue
                except Exception as exc:
                    record(task, None, _describe(exc), attempts[task.key])
                    continue
                record(task, outcome, None, attempts[task.key])
        # a broken pool: everything still in flight died with it
        return [*lost, *running.values()] if lost else []
    finally:
        if running or lost:  # interrupted or broken: don't wait for workers
            _kill_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)


def _kill_workers(pool: cf.ProcessPoolExecutor) -> None:
    # the executor has no public way to stop workers in the middle of an episode
    for process in list(getattr(pool, "_processes", {}).values()):
        process.kill()


def _run_on_dask(tasks: list[EpisodeTask], scheduler: str, runner: Runner, record: _Recorder,
                 tally: Tally, poll_s: float = 1.0) -> None:  # fmt: skip
    """A Dask cluster: twice as many episodes in flight as it has threads, so that its workers
    stay fed. Dask reruns the episodes of a worker that dies (giving up with ``KilledWorker``);
    the scheduler's count of episodes caught in a worker's death and the workers that vanished
    go into the tally."""
    client = _dask_client(scheduler)
    try:
        tally.slots = sum(client.nthreads().values()) or 1
        window = 2 * tally.slots
        pending = deque(tasks)
        running: dict[Any, EpisodeTask] = {}
        seen = set(client.scheduler_info()["workers"])
        prefix, suspicious_before = None, 0
        while pending or running:
            while pending and len(running) < window:
                task = pending.popleft()
                future = client.submit(runner, task, pure=False)
                running[future] = task
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
                task = running.pop(future)
                try:
                    outcome = future.result()
                except Exception as exc:
                    record(task, None, _describe(exc), 1)
                    continue
                record(task, outcome, None, 1)
        for future in running:
            future.cancel()
    finally:
        client.close()


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


def _check_workers(workers: int) -> None:
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


def run_experiment(
    plan: ExperimentPlan,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    runner: Runner = run_task,
) -> RunSummary:
    """Run what the store of ``plan.output_dir`` does not have yet; returns the counts."""
    _check_workers(workers)  # before hours of gallery and map building, not after
    check_methods(plan.spec.methods)
    t0 = time.perf_counter()
    with ResultStore(plan.output_dir, plan.name) as store:
        maps = prepare_maps(plan, progress, workers if scheduler is None else 1)
        tasks = [t.on_maps(maps) for t in plan.tasks()]
        _check_galleries(tasks, store)
        store.start_run(plan.spec.spec_hash, to_dict(plan), [t.key for t in tasks])
        done = store.done_keys()
        todo = [t for t in tasks if t.key not in done]
        logger.info(
            f"{plan.name}: {len(tasks)} episodes over {len(plan.setups)} setup(s); "
            f"{len(tasks) - len(todo)} already done, {len(todo)} to run"
        )
        t1 = time.perf_counter()
        e = execute(_order(todo), store, workers, scheduler, runner, progress=progress)
        return RunSummary(
            output_dir=plan.output_dir,
            total=len(tasks),
            skipped=len(tasks) - len(todo),
            finished=e.finished,
            errors=e.errors,
            retried=e.retried,
            workers_lost=e.workers_lost,
            wall_s=time.perf_counter() - t0,
            episodes_wall_s=time.perf_counter() - t1,
            episode_s=e.episode_s,
            store_s=e.store_s,
            slots=e.slots,
        )


def _check_galleries(tasks: Sequence[EpisodeTask], store: ResultStore) -> None:
    """A gallery's content is a cache check, not part of the episode keys: stored episodes driven
    with maps of another capture of a gallery (its index differs: captured again, and otherwise)
    are not mixed with episodes on the cached one."""
    stored = store.stored_map_dirs()
    for t in tasks:
        was = stored.get(t.key)
        if was and t.map_dir and Path(was).parent.name != Path(t.map_dir).parent.name:
            raise StoreError(
                f"{store.root}: episode {t.key} ({t.town}, {t.method_name}) was driven on the "
                f"gallery {Path(was).parent.name}, while the cache holds "
                f"{Path(t.map_dir).parent.name}: the gallery was captured again with other "
                "content. Run into another output folder, or restore the cache it was driven with"
            )


def _order(tasks: Iterable[EpisodeTask]) -> list[EpisodeTask]:
    """Longest first (visual failure episodes, then recall, then odometry only), by town and map
    within each kind so that consecutive episodes reuse the worker's scene and localizer."""
    rank = {"failure": 0, "recall": 1, "baseline": 2}
    return sorted(tasks, key=lambda t: (rank[t.kind], t.town, t.map_dir or "", t.key))
