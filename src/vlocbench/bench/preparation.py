"""Preparing a run: each town's gallery (a ground-truth drive) and each method's map on it, made
once and cached under the experiment's ``cache`` folder by a key of what determines them; with
several workers, the missing ones are made side by side in pool processes."""

from __future__ import annotations

import concurrent.futures as cf
import logging
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vlocbench.bench.executors import worker_pool
from vlocbench.bench.experiment import ExperimentPlan
from vlocbench.bench.gallery_capture import capture_gallery
from vlocbench.bench.methods import MethodSpec
from vlocbench.bench.platform import write_platform_file
from vlocbench.bench.progress import Progress, unit_of
from vlocbench.bench.towns import route_named, town_named
from vlocbench.loc.gallery import GALLERY_FILE, Gallery
from vlocbench.loc.mapping import (
    MAP_FILE,
    MappingConfig,
    MatchPool,
    build_map,
    default_map_dir,
    map_name,
    pools_matching,
)
from vlocbench.locks import building
from vlocbench.sim import Simulator

logger = logging.getLogger(__name__)


class StageBars:
    """The progress of each preparation stage (gallery images, features, matched pairs, maps),
    updated by the stages' callbacks and closed as each stage finishes; nothing when disabled."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bars: dict[str, Progress] = {}

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        if stage not in self.bars:
            self.bars[stage] = Progress(stage, total, unit_of(stage))
        self.bars[stage].update_to(done)
        if done >= total:  # finished: not drawn again when a later stage closes
            self.bars.pop(stage).close()

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def prepare_maps(
    plan: ExperimentPlan,
    progress: bool = False,
    workers: int = 1,
    only: Collection[tuple[str, str]] | None = None,
) -> dict[tuple[str, str], str]:
    """Capture each town's gallery and build each method's map, unless the cache has them; returns
    the map folders by (town, method name). ``only``: the (town, method name) pairs whose maps to
    build (default: all); the others' folders are where their maps lie or would be built, so a
    run can check its stored episodes before it builds what its remaining ones need. With
    ``workers`` > 1 the galleries, then the maps, are made side by side in as many processes (a
    gallery and a map build each use about one core)."""
    spec = plan.spec
    cache = Path(spec.cache).resolve()
    if not (spec.recall or spec.failure) or not any(m.needs_map for m in spec.methods):
        return {}  # no map to localize against, so no gallery either
    bars = StageBars(progress)
    try:
        if workers > 1:
            towns = [
                t for t in spec.towns if not (_gallery_dir(plan, t, cache) / GALLERY_FILE).exists()
            ]
            _in_parallel(
                _gallery_job, [(plan, t, cache) for t in towns], workers, bars, "galleries"
            )
        galleries = {t: _gallery(plan, t, cache, bars) for t in spec.towns}
        jobs = {}  # (town, method name) -> what _map builds it from
        for town in spec.towns:
            for method in (m for m in spec.methods if m.needs_map):
                mapping = method.mapping or spec.mapping
                map_dir = _map_dir(plan, cache, galleries[town], method)
                jobs[(town, method.name)] = (town, galleries[town], method, mapping, map_dir)
        build = [job for key, job in jobs.items() if only is None or key in only]
        if workers > 1:  # one build per folder: methods that localize differently share a map
            todo = list({j[-1]: j for j in build if not (j[-1] / MAP_FILE).exists()}.values())
            # one learned map alone: its images and pairs on every worker
            if len(todo) == 1 and pools_matching(todo[0][2].conf):
                with worker_pool(workers) as pool:
                    _map(*todo[0], bars, MatchPool(pool, workers))
            else:
                _in_parallel(_map_job, todo, workers, bars, "maps")
        for job in build:
            _map(*job, bars)
        return {key: str(job[-1]) for key, job in jobs.items()}
    finally:
        bars.close()


@dataclass(frozen=True)
class CachedMap:
    """A method's map of a town as the cache holds it."""

    finished: bool
    name: str  # its folder's name, what builds it (methods that differ only in localizing share it)
    folder: Path | None  # where it is (to be) built; None while its town's gallery is not captured
    images: int  # its gallery's images, or one a spacing of the route before its capture


def cached_preparation(
    plan: ExperimentPlan,
) -> tuple[dict[str, bool], dict[tuple[str, str], CachedMap]]:
    """Whether the cache holds each town's gallery, and each (town, method name)'s map; nothing
    is made."""
    cache = Path(plan.spec.cache).resolve()
    galleries, maps = {}, {}
    for town in plan.spec.towns:
        folder = _gallery_dir(plan, town, cache)
        galleries[town] = (folder / GALLERY_FILE).exists()
        gallery = Gallery.load(folder) if galleries[town] else None
        for method in (m for m in plan.spec.methods if m.needs_map):
            where = _map_dir(plan, cache, gallery, method) if gallery else None
            maps[(town, method.name)] = CachedMap(
                finished=where is not None and (where / MAP_FILE).exists(),
                name=map_name(method.conf, method.mapping or plan.spec.mapping),
                folder=where,
                images=len(gallery) if gallery else _shots(plan, town),
            )
    return galleries, maps


def _map_dir(plan: ExperimentPlan, cache: Path, gallery: Gallery, method: MethodSpec) -> Path:
    mapping = method.mapping or plan.spec.mapping
    return default_map_dir(cache / "maps", gallery, method.conf, mapping)


def prepare_gallery(plan: ExperimentPlan, town_name: str, progress: bool = False) -> Gallery:
    """The gallery of ``town_name`` as the experiment captures it, captured unless cached."""
    bars = StageBars(progress)
    try:
        return _gallery(plan, town_name, Path(plan.spec.cache).resolve(), bars)
    finally:
        bars.close()


def _in_parallel(
    job: Callable[..., object],
    args: list[tuple[Any, ...]],
    workers: int,
    bars: StageBars,
    stage: str,
) -> None:
    """``job(*a)`` for every ``a`` of ``args`` on a pool of pool workers (one thread each); a
    failure or an interruption stops the others. The jobs' own progress is not shown: one bar
    counts the jobs."""
    if len(args) < 2:
        return  # one job runs in the driver, with every thread
    logger.info(f"{len(args)} {stage} to make, {min(workers, len(args))} at a time")
    with worker_pool(min(workers, len(args))) as pool:
        futures = [pool.submit(job, *a) for a in args]
        for n, future in enumerate(cf.as_completed(futures), 1):
            future.result()
            bars(stage, n, len(args))


def _gallery_job(plan: ExperimentPlan, town_name: str, cache: Path) -> None:
    _gallery(plan, town_name, cache, StageBars(False))


def _map_job(
    town_name: str, gallery: Gallery, method: MethodSpec, mapping: MappingConfig, map_dir: Path
) -> None:
    _map(town_name, gallery, method, mapping, map_dir, StageBars(False))


def _gallery_dir(plan: ExperimentPlan, town_name: str, cache: Path) -> Path:
    return cache / "galleries" / plan.gallery_folder(town_name)


def _gallery(plan: ExperimentPlan, town_name: str, cache: Path, bars: StageBars) -> Gallery:
    spec, town = plan.spec, town_named(town_name)
    gallery_dir = _gallery_dir(plan, town_name, cache)
    with building(gallery_dir, "a gallery"):
        if not (gallery_dir / GALLERY_FILE).exists():
            logger.info(f"{town.name}: capturing the gallery in {gallery_dir}")
            t = time.perf_counter()
            route = route_named(town_name, spec.route_length_m)
            shots = _shots(plan, town_name)
            with Simulator(town, spec.gallery.conditions) as sim:
                capture_gallery(
                    sim,
                    route,
                    (spec.gallery.camera,),
                    gallery_dir,
                    spec.gallery.spacing_m,
                    spec.gallery.speed_mps,
                    progress=lambda n: bars(f"{town.name} gallery", n, shots),
                )
            write_platform_file(gallery_dir)
            logger.info(f"{town.name}: gallery captured in {time.perf_counter() - t:.0f} s")
    return Gallery.load(gallery_dir)


def _shots(plan: ExperimentPlan, town_name: str) -> int:
    """The images of the town's gallery: one every ``gallery.spacing_m`` of its route (the
    capture stops where the drive ends the route, at most this many)."""
    route = route_named(town_name, plan.spec.route_length_m)
    return int(route.length_m / plan.spec.gallery.spacing_m) + 1


def _map(
    town_name: str,
    gallery: Gallery,
    method: MethodSpec,
    mapping: MappingConfig,
    map_dir: Path,
    bars: StageBars,
    pool: MatchPool | None = None,
) -> Path:
    """The map of ``method`` on the town's ``gallery`` in ``map_dir``, built unless it is there
    (``pool``: processes that extract its features and match its pairs)."""
    name = town_named(town_name).name
    built_here = not (map_dir / MAP_FILE).exists()
    if built_here:
        logger.info(f"{name}: building the {method.name} map in {map_dir}")
    label = f"{name} {method.name}"
    report = build_map(
        gallery,
        method.conf,
        map_dir,
        mapping,
        progress=lambda stage, done, total: bars(f"{label} {stage}", done, total),
        pool=pool,
    )
    if built_here:
        write_platform_file(map_dir, gallery.root)
    logger.info(f"{name}: {method.name} map: {report.images} images, {report.points} points")
    return map_dir
