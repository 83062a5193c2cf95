"""The cache that experiments share (``cache:``, ``out/cache`` by default): each town's gallery and
each method's map on it, kept by a key of what determines them. A change of the towns' look or of a
method's settings leaves the old ones behind, a few hundred megabytes each; this module lists what
the cache holds and what a set of experiments still uses, so that the rest can be freed."""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from vlocbench.bench.experiment import ExperimentPlan
from vlocbench.bench.platform import read_platform_file
from vlocbench.loc.gallery import GALLERY_FILE, Gallery
from vlocbench.locks import unless_building

GALLERIES, MAPS = "galleries", "maps"


@dataclass(frozen=True)
class CacheEntry:
    """One gallery (``galleries/TOWN-KEY``) or map (``maps/GALLERY-ID/MAP``) of the cache."""

    kind: Literal["gallery", "map"]
    path: Path
    size_bytes: int
    modified_s: float  # the newest file's modification time, seconds since the epoch

    @property
    def platform(self) -> str | None:
        """The id of the platform that made it (None: made before platforms were recorded)."""
        made = read_platform_file(self.path).get("made_on")
        return made["id"] if made else None

    @property
    def name(self) -> str:
        """The entry's path inside the cache: ``galleries/town10-e251e46482``."""
        depth = 2 if self.kind == "gallery" else 3
        return "/".join(self.path.parts[-depth:])


def entries(cache: str | Path) -> list[CacheEntry]:
    """Every gallery and map under ``cache``, galleries first, each kind by name."""
    cache = Path(cache)
    galleries = sorted(p for p in (cache / GALLERIES).glob("*") if p.is_dir())
    maps = sorted(p for p in (cache / MAPS).glob("*/*") if p.is_dir())
    return [_entry("gallery", p) for p in galleries] + [_entry("map", p) for p in maps]


def used_by(plans: Iterable[ExperimentPlan], cache: str | Path) -> set[Path]:
    """The galleries and maps under ``cache`` that ``plans`` would use: each town's gallery and,
    where the gallery is there, each method's map on it (a map's folder is keyed by its gallery's
    content, so the maps of a gallery captured again are not among them)."""
    cache = Path(cache).resolve()
    used: set[Path] = set()
    for plan in plans:
        if Path(plan.spec.cache).resolve() != cache:
            continue  # its galleries and maps lie in another cache
        for town in plan.spec.towns:
            gallery_dir = cache / GALLERIES / plan.gallery_folder(town)
            used.add(gallery_dir)
            if not (gallery_dir / GALLERY_FILE).exists():
                continue
            identity = Gallery.load(gallery_dir).identity
            used.update(
                cache / MAPS / identity / plan.map_name(m) for m in plan.spec.methods if m.needs_map
            )
    return used


def unused(
    cache: str | Path,
    plans: Sequence[ExperimentPlan],
    among: Sequence[CacheEntry] | None = None,
) -> list[CacheEntry]:
    """The entries of ``cache`` (or those of ``among``, already listed) that none of ``plans``
    uses."""
    keep = used_by(plans, cache)
    return [e for e in (entries(cache) if among is None else among) if e.path.resolve() not in keep]


def delete(entry: CacheEntry) -> bool:
    """Remove ``entry``; False, and nothing removed, while a process is building it."""
    with unless_building(entry.path) as free:
        if free:
            shutil.rmtree(entry.path)
    return free


def _entry(kind: Literal["gallery", "map"], path: Path) -> CacheEntry:
    size, newest = 0, path.stat().st_mtime
    for root, _, files in os.walk(path):
        for name in files:
            stat = Path(root, name).stat()
            size += stat.st_size
            newest = max(newest, stat.st_mtime)
    return CacheEntry(kind, path, size, newest)
