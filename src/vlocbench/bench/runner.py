"""Running an experiment: galleries and maps (built once, reused), then every episode not yet in
the store, on a local process pool or a Dask cluster; the driver alone writes the store.

Workers get an :class:`EpisodeTask` and return an :class:`EpisodeOutcome`; they keep a town, a
simulator and the last localizer per process, so consecutive episodes skip the scene build and the
map load. A worker process that dies (a crash, the OOM killer) has its episode retried up to
``max_attempts`` times; an episode that raises is recorded with its error and the run goes on.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from vlocbench.bench.episode import plan_town_route, run_episode
from vlocbench.bench.experiment import EpisodeTask, ExperimentSpec, expand, gallery_key, setups
from vlocbench.bench.gallery_capture import capture_gallery
from vlocbench.bench.metrics import episode_metrics
from vlocbench.bench.records import EpisodeResult
from vlocbench.bench.store import EpisodeRow, ResultStore
from vlocbench.config import to_dict
from vlocbench.errors import ConfigError
from vlocbench.loc.gallery import GALLERY_FILE, Gallery
from vlocbench.loc.mapping import MAP_FILE, build_map, default_map_dir
from vlocbench.nav import WaypointPath
from vlocbench.sim import Simulator
from vlocbench.sim.town import Town, generate_town, load_town_spec

Log = Callable[[str], None]
CONNECT_TIMEOUT_S = 10  # to a Dask scheduler


@dataclass(frozen=True)
class EpisodeOutcome:
    key: str
    result: EpisodeResult
    wall_s: float  # in the worker, town and map loading included


@dataclass(frozen=True)
class Execution:
    """What :func:`execute` did: episodes finished, ended in an error and rerun after their worker
    died; seconds in episodes (summed over workers) and writing; the most episodes at once."""

    finished: int
    errors: int
    retried: int
    episode_s: float
    store_s: float
    slots: int


@dataclass(frozen=True)
class RunSummary:
    output_dir: Path
    total: int
    skipped: int  # finished in an earlier run
    finished: int
    errors: int
    retried: int  # episodes rerun after their worker died
    wall_s: float  # the whole run, galleries and maps included
    episodes_wall_s: float  # the episode phase
    episode_s: float  # the sum of the episodes' times in their workers
    store_s: float  # the driver's time writing results (metrics, Parquet, SQLite)
    slots: int  # episodes that could run at once: local workers, or the Dask cluster's threads

    @property
    def harness_overhead(self) -> float:
        """Episode-phase time beyond the workers' episode time, as a fraction of the latter
        (storing, scheduling, transfers, idle workers at the end)."""
        busy = self.episode_s / self.slots
        return 0.0 if busy <= 0 else max(0.0, self.episodes_wall_s / busy - 1)

    @property
    def store_overhead(self) -> float:
        """The driver's writing time as a fraction of the episodes' time."""
        return 0.0 if self.episode_s <= 0 else self.store_s / self.episode_s


# -- the worker side ------------------------------------------------------------------------------
@lru_cache(maxsize=4)
def _town(name: str) -> Town:
    return generate_town(load_town_spec(name))


@lru_cache(maxsize=4)
def _route(name: str, length_m: float = 0.0) -> WaypointPath:
    """The town's route, cut after its first ``length_m`` metres when that is > 0."""
    return plan_town_route(_town(name)).head(length_m)


_SIM: dict[tuple[str, Any], Simulator] = {}
_LOCALIZER: dict[Any, Any] = {}


def _simulator(task: EpisodeTask) -> Simulator:
    """One simulator per town and traffic slot count in this process; conditions are switched."""
    key = (task.town, task.setup.conditions.traffic)
    sim = _SIM.get(key)
    if sim is None:
        for old in list(_SIM):
            if old[0] == task.town:  # keep one scene per town in memory
                _SIM.pop(old).close()
        sim = _SIM[key] = Simulator(_town(task.town), task.setup.conditions)
    else:
        sim.set_conditions(task.setup.conditions)
    return sim


def _localizer(task: EpisodeTask) -> Any:
    """The last visual localizer of this process, reloaded only when map, config or rig change."""
    if task.method is None:
        return None
    from vlocbench.bench.visual import VisualLocalizer

    key = (task.map_dir, task.method.localizer, task.setup.cameras)
    if key not in _LOCALIZER:
        _LOCALIZER.clear()
        _LOCALIZER[key] = VisualLocalizer(
            task.map_dir, task.setup.cameras, task.method.localizer, task.method.name
        )
    return _LOCALIZER[key]


def run_task(task: EpisodeTask) -> EpisodeOutcome:
    """Run one episode in this process (the function workers execute)."""
    t = time.perf_counter()
    localizer = _localizer(task)
    result = run_episode(
        _simulator(task), _route(task.town, task.route_length_m), localizer, task.episode
    )
    return EpisodeOutcome(task.key, result, time.perf_counter() - t)


def _worker_init() -> None:
    # one process per core: OpenMP threads spinning against each other make torch crawl. Set
    # before torch is imported (by the first localizer), which reads it then.
    os.environ["OMP_NUM_THREADS"] = "1"


# -- the driver side ------------------------------------------------------------------------------
def prepare_maps(spec: ExperimentSpec, log: Log = print) -> dict[tuple[str, str], str]:
    """Capture each town's gallery and build each method's map, unless the cache has them."""
    cache = Path(spec.cache).resolve()
    out: dict[tuple[str, str], str] = {}
    if not (spec.recall or spec.failure):
        return out
    for town_name in spec.towns:
        town = _town(town_name)
        gallery_dir = cache / "galleries" / f"{town.name}-{gallery_key(town_name, spec)}"
        if not (gallery_dir / GALLERY_FILE).exists():
            log(f"{town.name}: capturing the gallery in {gallery_dir}")
            t = time.perf_counter()
            sim = Simulator(town, spec.gallery.conditions)
            try:
                route = _route(town_name, spec.route_length_m)
                capture_gallery(sim, route, (spec.gallery.camera,), gallery_dir,
                                spec.gallery.spacing_m, spec.gallery.speed_mps)  # fmt: skip
            finally:
                sim.close()
            log(f"{town.name}: gallery captured in {time.perf_counter() - t:.0f} s")
        gallery = Gallery.load(gallery_dir)
        for method in spec.methods:
            mapping = method.mapping or spec.mapping
            map_dir = default_map_dir(cache / "maps", gallery, method.name, method.conf, mapping)
            if not (map_dir / MAP_FILE).exists():
                log(f"{town.name}: building the {method.name} map in {map_dir}")
            report = build_map(gallery, method.conf, map_dir, mapping)
            log(f"{town.name}: {method.name} map: {report.images} images, {report.points} points")
            out[(town_name, method.name)] = str(map_dir)
    return out


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
        "config_hash": task.key,
    }
    metrics = asdict(episode_metrics(outcome.result)) if outcome else None
    return EpisodeRow(
        task.key, task.kind, _town(task.town).name, task.method_name, task.setup.label, task.repetition,
        task.episode.seed, config, "ok" if outcome else "error", error, metrics,
        outcome.wall_s if outcome else None, attempts,
    )  # fmt: skip


class _Progress:
    def __init__(self, total: int, enabled: bool) -> None:
        self.bar = None
        if enabled and total:
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="episode", dynamic_ncols=True)

    def update(self, ok: int, errors: int, task: EpisodeTask) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(f"ok {ok} err {errors} | {task.town} {task.method_name} "
                                     f"{task.kind}", refresh=False)  # fmt: skip
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _local_pool(workers: int) -> cf.Executor:
    return cf.ProcessPoolExecutor(
        workers, mp_context=multiprocessing.get_context("spawn"), initializer=_worker_init
    )


def execute(
    tasks: list[EpisodeTask],
    store: ResultStore,
    workers: int = 1,
    scheduler: str | None = None,
    runner: Callable[[EpisodeTask], EpisodeOutcome] = run_task,
    max_attempts: int = 3,
    progress: bool = True,
) -> Execution:
    """Run ``tasks``, writing each outcome as it arrives.

    ``workers == 1`` without a scheduler runs in this process. Otherwise at most one episode per
    worker is in flight, so a worker that dies takes only the episodes in flight with it: they are
    run again (up to ``max_attempts`` in all) on a fresh pool; Dask reschedules them itself.
    """
    _check_workers(workers)
    bar = _Progress(len(tasks), progress)
    finished = errors = retried = 0
    episode_s = store_s = 0.0
    slots = workers

    def record(task: EpisodeTask, outcome: EpisodeOutcome | None, error: str | None,
               attempts: int) -> None:  # fmt: skip
        nonlocal finished, errors, episode_s, store_s
        t = time.perf_counter()
        store.write_episode(_row(task, outcome, error, attempts),
                            outcome.result if outcome else None)  # fmt: skip
        store_s += time.perf_counter() - t
        if outcome:
            finished += 1
            episode_s += outcome.wall_s
        else:
            errors += 1
        bar.update(finished, errors, task)

    try:
        if scheduler is None and workers == 1:
            for task in tasks:
                try:
                    outcome = runner(task)
                except Exception:  # an episode's bug must not end the run: record it
                    record(task, None, traceback.format_exc(limit=8), 1)
                    continue
                record(task, outcome, None, 1)
            return Execution(finished, errors, retried, episode_s, store_s, slots)
        attempts = dict.fromkeys((t.key for t in tasks), 0)
        pending = deque(tasks)
        while pending:
            executor, client, slots = _executor(workers, scheduler)
            window = slots if client is None else 2 * slots  # Dask: keep its workers fed
            running: dict[cf.Future, EpisodeTask] = {}
            lost: list[EpisodeTask] = []
            interrupted = True  # until the loop ends normally (Ctrl-C, a store error)
            try:
                while pending or running:
                    while pending and len(running) < window:
                        task = pending.popleft()
                        attempts[task.key] += 1
                        running[executor.submit(runner, task)] = task
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
                    if lost:  # the pool is broken: everything in flight died with it
                        lost += running.values()
                        running = {}
                        for task in lost:
                            if attempts[task.key] < max_attempts:
                                pending.appendleft(task)
                                retried += 1
                            else:
                                record(task, None, "its worker process died", attempts[task.key])
                        break
                interrupted = False
            finally:
                if client is None:
                    if lost or interrupted:  # don't wait for workers that are dead or not needed
                        for process in list(getattr(executor, "_processes", {}).values()):
                            process.kill()
                    executor.shutdown(wait=True, cancel_futures=True)
                else:
                    for future in running:
                        future.cancel()
                    client.close()
        return Execution(finished, errors, retried, episode_s, store_s, slots)
    finally:
        bar.close()


def _check_workers(workers: int) -> None:
    if workers < 1:
        raise ConfigError("--workers", f"must be >= 1, got {workers}")


def _describe(exc: BaseException) -> str:
    if type(exc).__name__ == "KilledWorker":  # Dask gave up after its own retries
        return f"its worker died on every attempt ({exc})"
    return "".join(traceback.format_exception(exc, limit=8))


def _executor(workers: int, scheduler: str | None) -> tuple[cf.Executor, Any, int]:
    """The executor, its Dask client (or None) and how many episodes it runs at once."""
    if scheduler is None:
        return _local_pool(workers), None, workers
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError(
            "--scheduler", "Dask is not installed: pip install 'vlocbench[dask]'"
        ) from None
    try:
        client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
    except OSError as exc:
        raise ConfigError("--scheduler", f"cannot reach {scheduler}: {exc}") from None
    threads = sum(client.nthreads().values()) or workers
    return client.get_executor(pure=False), client, threads


def run_experiment(
    spec: ExperimentSpec,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    log: Log = print,
    runner: Callable[[EpisodeTask], EpisodeOutcome] = run_task,
) -> RunSummary:
    """Run what the store of ``spec.output_dir`` does not have yet; returns the counts."""
    _check_workers(workers)  # before hours of gallery and map building, not after
    t0 = time.perf_counter()
    with ResultStore(spec.output_dir, spec.name) as store:
        maps = prepare_maps(spec, log)
        tasks = expand(spec, maps)
        store.start_run(spec.spec_hash, to_dict(spec), [t.key for t in tasks])
        done = store.done_keys()
        todo = [t for t in tasks if t.key not in done]
        log(
            f"{spec.name}: {len(tasks)} episodes over {len(setups(spec))} setup(s); "
            f"{len(tasks) - len(todo)} already done, {len(todo)} to run"
        )
        t1 = time.perf_counter()
        e = execute(_order(todo), store, workers, scheduler, runner, progress=progress)
        return RunSummary(
            spec.output_dir, len(tasks), len(tasks) - len(todo), e.finished, e.errors, e.retried,
            time.perf_counter() - t0, time.perf_counter() - t1, e.episode_s, e.store_s, e.slots,
        )  # fmt: skip


def _order(tasks: Iterable[EpisodeTask]) -> list[EpisodeTask]:
    """Longest first (visual failure episodes, then recall, then odometry only), by town and map
    within each kind so that consecutive episodes reuse the worker's scene and localizer."""
    rank = {"failure": 0, "recall": 1, "baseline": 2}
    return sorted(tasks, key=lambda t: (rank[t.kind], t.town, t.map_dir or "", t.key))
