"""Running an experiment: its galleries and maps (:mod:`vlocbench.bench.preparation`), then every
episode not yet in the store on an executor (:mod:`vlocbench.bench.executors`); what a run did
comes back as a :class:`RunSummary`."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from vlocbench.bench.executors import Runner, check_workers, execute
from vlocbench.bench.experiment import EpisodeTask, ExperimentPlan
from vlocbench.bench.methods import check_methods
from vlocbench.bench.platform import current_platform
from vlocbench.bench.preparation import prepare_maps
from vlocbench.bench.store import ResultStore, StoreError, read_map_dirs, run_hash
from vlocbench.bench.worker import run_job
from vlocbench.config import to_dict

logger = logging.getLogger(__name__)


@dataclass(frozen=True, kw_only=True)
class RunSummary:
    output_dir: Path
    total: int
    skipped: int  # finished in an earlier run
    reused: int  # of them, taken from other experiments' stores in this run (``reuse``)
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


def run_experiment(
    plan: ExperimentPlan,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = True,
    runner: Runner = run_job,
    share_drives: bool = True,
    reuse: Sequence[str | Path] = (),
) -> RunSummary:
    """Run what the store of ``plan.output_dir`` does not have yet; returns the counts.
    ``reuse``: output folders of other experiments whose finished episodes this plan shares
    (the same keys: the same towns, conditions, methods, maps and seeds) are copied from them
    instead of driven again. ``share_drives=False`` drives every recall episode on its own (see
    :mod:`vlocbench.bench.shared_drive`), for measuring what sharing saves."""
    check_workers(workers)  # before hours of gallery and map building, not after
    check_methods(plan.spec.methods)
    for mismatch in plan.camera_mismatches():
        logger.warning(f"{plan.name}: {mismatch}")
    t0 = time.perf_counter()
    pool = workers if scheduler is None else 1
    with ResultStore(plan.output_dir, plan.name) as store:
        # the galleries first: the stored episodes are checked against them before any map is
        # built, and only the maps of episodes still to drive are (hours for a learned method)
        maps = prepare_maps(plan, progress, pool, only=())
        tasks = [t.on_maps(maps) for t in plan.tasks()]
        _check_galleries(tasks, store)
        keys = [t.key for t in tasks]
        store.start_run(run_hash(keys), to_dict(plan), keys)
        reused = sum(_reuse(plan, tasks, store, Path(source)) for source in reuse)
        done = store.done_keys()
        todo = [t for t in tasks if t.key not in done]
        logger.info(
            f"{plan.name}: {len(tasks)} episodes over {len(plan.setups)} setup(s); "
            f"{len(tasks) - len(todo)} already done"
            + (f" ({reused} of them taken from other stores)" if reuse else "")
            + f", {len(todo)} to run"
        )
        needed = {(t.town, t.method.name) for t in todo if t.method and t.method.needs_map}
        if needed:
            prepare_maps(plan, progress, pool, only=needed)
        if todo:
            _check_platform(plan, store)
        t1 = time.perf_counter()
        e = execute(
            _order(todo),
            store,
            workers,
            scheduler,
            runner,
            progress=progress,
            share_drives=share_drives,
        )
        return RunSummary(
            output_dir=plan.output_dir,
            total=len(tasks),
            skipped=len(tasks) - len(todo),
            reused=reused,
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
        other = _other_gallery(t, stored.get(t.key))
        if other:
            raise StoreError(
                f"{store.root}: episode {t.key} ({t.town}, {t.method_name}) was driven on the "
                f"gallery {other[0]}, while the cache holds {other[1]}: the gallery was captured "
                "again with other content. Run into another output folder, or restore the cache "
                "it was driven with"
            )


def _other_gallery(task: EpisodeTask, stored_map_dir: str | None) -> tuple[str, str] | None:
    """(the gallery it was driven on, the cache's) where a stored episode of ``task``, driven on
    the map in ``stored_map_dir``, was driven on another capture of its gallery than the cache
    holds (a map's folder lies in its gallery's); else None."""
    if not (stored_map_dir and task.map_dir):
        return None
    was, now = Path(stored_map_dir).parent.name, Path(task.map_dir).parent.name
    return (was, now) if was != now else None


def _reuse(
    plan: ExperimentPlan, tasks: Sequence[EpisodeTask], store: ResultStore, source: Path
) -> int:
    """Copy into ``store`` the episodes of ``tasks`` that the store in ``source`` finished and
    it has not; those driven on another capture of a gallery than the cache's are left to run
    (as :func:`_check_galleries` would refuse them). Returns how many it copied."""
    driven_on = read_map_dirs(source)
    keys = [t.key for t in tasks if not _other_gallery(t, driven_on.get(t.key))]
    copied = store.adopt(source, keys)
    if copied:
        logger.info(f"{plan.name}: {len(copied)} episodes taken from {source} (the same keys)")
    return len(copied)


def _check_platform(plan: ExperimentPlan, store: ResultStore) -> None:
    """Warn when the episodes about to run join stored ones of other platforms only (a store
    carried to another machine): their numbers need not agree to the last digit, or beyond."""
    stored = {p: n for p, n in store.platform_counts().items() if p}
    if not stored:
        return
    here = current_platform().id  # a few seconds, once a process: only where there is a record
    if here not in stored:
        ran_on = ", ".join(f"{n} on {p}" for p, n in sorted(stored.items()))
        logger.warning(
            f"{plan.name}: this machine is platform {here}; the store's episodes ran on others "
            f"({ran_on}): its renders and kernels may differ, and so may the numbers (`vlocbench "
            f"platform {store.root}` compares them)"
        )


def _order(tasks: Iterable[EpisodeTask]) -> list[EpisodeTask]:
    """Longest first (visual failure episodes, then recall, then odometry only), by town and map
    within each kind so that consecutive episodes reuse the worker's scene and localizer."""
    rank = {"failure": 0, "recall": 1, "baseline": 2}
    return sorted(tasks, key=lambda t: (rank[t.kind], t.town, t.map_dir or "", t.key))
