"""What a run of an experiment would do, without doing it (``vlocbench run FILE --dry-run``): its
episodes already in the store or in the stores it would reuse, those left to drive, the galleries
and maps it would make, and the worker time the maps and the drives would take, estimated from
the cache's finished maps of the same kind and from the wall times of the finished episodes of
the store and of those it would reuse. Reads the stores and caches without their locks (a run may
be writing), makes and writes nothing."""

from __future__ import annotations

import statistics
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from vlocbench.bench.experiment import EpisodeTask, ExperimentPlan
from vlocbench.bench.preparation import cached_preparation
from vlocbench.bench.store import DB_FILE, EpisodeRow, read_episodes
from vlocbench.bench.towns import route_named, town_named
from vlocbench.loc.mapping import build_seconds


@dataclass(frozen=True)
class EpisodeGroup:
    """A town's episodes of one method and kind: how many the plan has, how many are done, and
    the seconds one takes (None: no time to go by)."""

    town: str
    method: str  # "odometry" for the odometry-only drives
    kind: str
    planned: int
    done: int
    episode_s: float | None
    estimated: bool  # episode_s from the method's drives in other towns, per metre of route

    @property
    def to_run(self) -> int:
        return self.planned - self.done


@dataclass(frozen=True)
class MapBuild:
    """A map a run would build (or finish), and a worker's seconds for it (None: no finished map
    of its kind in the cache to go by)."""

    town: str
    method: str
    worker_s: float | None


@dataclass(frozen=True)
class Forecast:
    """What :func:`forecast` found."""

    experiment: str
    output_dir: Path
    groups: tuple[EpisodeGroup, ...]
    reusable: int  # of the done, how many a run would copy from the ``reuse`` stores
    galleries_to_make: tuple[str, ...]  # towns
    maps_to_build: tuple[MapBuild, ...]
    map_worker_s: float  # of the maps to build with a time to go by, each folder once

    @property
    def planned(self) -> int:
        return sum(g.planned for g in self.groups)

    @property
    def to_run(self) -> int:
        return sum(g.to_run for g in self.groups)

    @property
    def worker_s(self) -> float:
        """Worker-seconds of the episodes left to drive that have a time to go by."""
        return sum(g.to_run * g.episode_s for g in self.groups if g.episode_s is not None)

    @property
    def untimed(self) -> int:
        """Episodes left to drive with no time to go by."""
        return sum(g.to_run for g in self.groups if g.episode_s is None)

    def lines(self, workers: int) -> list[str]:
        """The forecast as text: the counts, what to make, a line per method and kind with
        episodes left, and the maps' and the drives' time on ``workers`` workers."""
        out = [
            f"{self.experiment} ({self.output_dir}): {self.planned} episodes, "
            f"{self.planned - self.to_run} done"
            + (f" ({self.reusable} of them to copy from other stores)" if self.reusable else "")
            + f", {self.to_run} to run"
        ]
        if self.galleries_to_make:
            out.append(f"galleries to capture: {', '.join(self.galleries_to_make)}")
        if self.maps_to_build:
            out.append("maps to build: " + ", ".join(map(_build, self.maps_to_build)))
        by_kind: dict[tuple[str, str], list[EpisodeGroup]] = defaultdict(list)
        for g in self.groups:
            by_kind[(g.method, g.kind)].append(g)
        for (method, kind), groups in by_kind.items():
            if any(g.to_run for g in groups):
                out.append(f"  {method} {kind}: {_left(groups)}")
        if self.map_worker_s:
            out.append(
                f"maps: ~{_span(self.map_worker_s)} of a worker, "
                f"~{_span(self.map_worker_s / workers)} on {workers} worker(s)"
            )
        if self.to_run:
            wall = f", {_span(self.worker_s / workers)} on {workers} worker(s)"
            out.append(f"all: {_left(self.groups)}" + (wall if self.worker_s else ""))
        if self.worker_s or self.map_worker_s:
            on_top = [
                *(["the galleries"] if self.galleries_to_make else []),
                *(
                    ["the maps without a time"]
                    if any(b.worker_s is None for b in self.maps_to_build)
                    else []
                ),
            ]
            out.append(
                "(times: the median wall time of the finished episodes of each town, method and "
                "kind, as their workers drove them; ~: of the method's in other towns, per metre "
                "of route"
                + (
                    "; maps: the median rates of the cache's finished maps of the same kind, per "
                    "image and pair, less what their folders hold"
                    if self.map_worker_s
                    else ""
                )
                + (f"; {' and '.join(on_top)} come on top)" if on_top else ")")
            )
        return out


def _build(b: MapBuild) -> str:
    return f"{b.town} {b.method}" + (f" (~{_span(b.worker_s)})" if b.worker_s is not None else "")


def _left(groups: Sequence[EpisodeGroup]) -> str:
    """How many of ``groups``' episodes are left, and the worker time they take."""
    left = [g for g in groups if g.to_run]
    timed = [g for g in left if g.episode_s is not None]
    seconds = sum(g.to_run * (g.episode_s or 0.0) for g in timed)
    untimed = sum(g.to_run for g in left) - sum(g.to_run for g in timed)
    text = f"{sum(g.to_run for g in left)} of {sum(g.planned for g in groups)} left"
    if timed:
        text += f", {'~' if any(g.estimated for g in timed) else ''}{_span(seconds)} of a worker"
    return text + (f", {untimed} with no time yet" if untimed else "")


def _span(seconds: float) -> str:
    return f"{seconds / 3600:.1f} h" if seconds >= 3600 else f"{seconds / 60:.0f} min"


def forecast(plan: ExperimentPlan, reuse: Sequence[str | Path] = ()) -> Forecast:
    """What ``vlocbench run`` would do for ``plan`` (with ``reuse``'s stores), read from its
    store and the cache; nothing is made or written."""
    tasks = plan.tasks()
    stored = _finished(plan.output_dir) if (plan.output_dir / DB_FILE).is_file() else {}
    # a reuse folder that is not a store is an error, as for the run
    others = {k: r for s in reuse for k, r in _finished(Path(s)).items() if k not in stored}
    done = stored.keys() | others.keys()
    todo = [t for t in tasks if t.key not in done]
    galleries, maps = cached_preparation(plan)
    needed = {(t.town, t.method.name) for t in todo if t.method and t.method.needs_map}
    # as the store names them; once a town (its generation is cached for fewer towns than a set's)
    name = {t: town_named(t).name for t in plan.spec.towns}
    maps_root = Path(plan.spec.cache).resolve() / "maps"
    left = sorted((t, method) for t, method in needed if not maps[t, method].finished)
    seconds: dict[tuple[str, str], float | None] = {}  # a build a folder, shared by methods
    for t, method in left:  # that differ only in how they localize
        m = maps[t, method]
        if (t, m.name) not in seconds:
            seconds[t, m.name] = build_seconds(maps_root, m.name, m.images, m.folder)
    builds = tuple(MapBuild(name[t], m, seconds[t, maps[t, m].name]) for t, m in left)
    return Forecast(
        experiment=plan.name,
        output_dir=plan.output_dir,
        groups=_groups(plan, name, tasks, done, [*stored.values(), *others.values()]),
        reusable=sum(t.key in others for t in tasks),
        galleries_to_make=tuple(
            name[t] for t in name if not galleries[t] and any(p[0] == t for p in needed)
        ),
        maps_to_build=builds,
        map_worker_s=sum(s for s in seconds.values() if s is not None),
    )


def _finished(output_dir: Path) -> dict[str, EpisodeRow]:
    return {r.key: r for r in read_episodes(output_dir) if r.status == "ok"}


def _groups(
    plan: ExperimentPlan,
    name: dict[str, str],
    tasks: Sequence[EpisodeTask],
    done: set[str],
    stored: Sequence[EpisodeRow],
) -> tuple[EpisodeGroup, ...]:
    length_m = {name[t]: route_named(t, plan.spec.route_length_m).length_m for t in name}
    seconds: dict[tuple[str, str, str], list[float]] = defaultdict(list)
    per_m: dict[tuple[str, str], list[float]] = defaultdict(list)
    for r in stored:
        if r.wall_s is not None and r.town in length_m:
            seconds[(r.town, r.method, r.kind)].append(r.wall_s)
            per_m[(r.method, r.kind)].append(r.wall_s / length_m[r.town])
    counts: dict[tuple[str, str, str], list[int]] = defaultdict(lambda: [0, 0])
    for t in tasks:
        c = counts[(name[t.town], t.method_name, t.kind)]
        c[0] += 1
        c[1] += t.key in done
    groups = []
    for (town, method, kind), (planned, n_done) in counts.items():
        own, other = seconds.get((town, method, kind)), per_m.get((method, kind))
        episode_s = (
            statistics.median(own)
            if own
            else statistics.median(other) * length_m[town]
            if other
            else None
        )
        groups.append(
            EpisodeGroup(town, method, kind, planned, n_done, episode_s, not own and bool(other))
        )
    return tuple(groups)
