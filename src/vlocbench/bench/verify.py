"""Driving stored episodes again: does this code, on this machine, give a store's numbers?

An episode's key names what determines it, and the same key must give the same numbers: a change
of the code that changes a drive bumps a version, so that its episodes get new keys (the stores
keep results across sessions and code changes). Nothing but driving it again checks that a store's
episodes still are what their keys say. :func:`verify_episodes` drives stored episodes again, in
this process and without writing, against the map each was driven with, and compares the result
with the stored one to the last digit: its metrics (measured times aside), every step of its
trajectory and every localization (the computation's own time aside). Where the platform differs
from the stored episode's (:mod:`vlocbench.bench.platform`), a difference is expected and is said
to be; a drive whose latency is the measured computation time follows the machine's load and is
not compared.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vlocbench.bench.experiment import EpisodeTask
from vlocbench.bench.metrics import episode_metrics
from vlocbench.bench.platform import current_platform
from vlocbench.bench.records import EPISODE_KINDS, EpisodeResult, localization_columns
from vlocbench.bench.runs import Experiment, stored_episodes
from vlocbench.bench.store import EpisodeRow, StoreError, read_episode_table
from vlocbench.bench.worker import run_job
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.loc.mapping import MAP_FILE

# what a drive measures of the machine, not of the drive: never the same twice
_TIMING_METRICS = ("ct_", "wall_time_s")  # name prefixes: ct_mean_s, ct_matching_ms, ...
_TIMING_COLUMNS = ("compute_time_s", "stage_s")


@dataclass(frozen=True, kw_only=True)
class Verdict:
    """One stored episode driven again. ``same``: equal to the last digit (None: not compared,
    see ``differences``); ``differences``: what differs, first the metrics, then the first step
    of the trajectory and the first localization that differ."""

    row: EpisodeRow
    same: bool | None
    differences: tuple[str, ...]
    platform: str  # this machine's platform id
    wall_s: float

    @property
    def same_platform(self) -> bool:
        return self.row.platform == self.platform

    def line(self) -> str:
        r = self.row
        what = f"{r.town} {r.method} {r.kind} {r.setup} rep {r.repetition} ({r.key})"
        if self.same is None:
            return f"{what}: not compared, {'; '.join(self.differences)}"
        if self.same:
            return f"{what}: the same to the last digit ({self.wall_s / 60:.1f} min)"
        where = (
            "on this platform, as it was stored: the code changed what this key drives"
            if self.same_platform
            else "stored on "
            + (f"platform {r.platform}" if r.platform else "an unrecorded platform")
            + f", driven again on {self.platform}: expected where renders or kernels differ"
        )
        return f"{what}: DIFFERS {where}; " + "; ".join(self.differences)


def pick_episodes(
    rows: Sequence[EpisodeRow],
    count: int,
    kinds: Sequence[str] = (),
    keys: Sequence[str] = (),
    seed: int = 0,
    methods: Sequence[str] = (),
) -> list[EpisodeRow]:
    """The finished episodes to drive again: those of ``keys``, else ``count`` of ``kinds`` and
    ``methods`` (all by default; the odometry line is the method ``odometry``) drawn with
    ``seed``, in key order."""
    for kind in kinds:
        if kind not in EPISODE_KINDS:
            raise UnknownNameError("episode kind", kind, EPISODE_KINDS, "--kinds")
    done = [r for r in rows if r.status == "ok"]
    if keys:
        by_key = {r.key: r for r in done}
        missing = [k for k in keys if k not in by_key]
        if missing:
            raise ConfigError("--key", f"no finished episode of this store has key {missing[0]}")
        return [by_key[k] for k in keys]
    stored_methods = sorted({r.method for r in done})
    for method in methods:
        if method not in stored_methods:
            raise UnknownNameError("method", method, stored_methods, "--methods")
    pool = [
        r for r in done if (not kinds or r.kind in kinds) and (not methods or r.method in methods)
    ]
    if not pool:
        raise ConfigError("--kinds", f"no finished episode of kinds {', '.join(kinds)} stored")
    chosen = np.random.default_rng(seed).choice(len(pool), min(count, len(pool)), replace=False)
    return [pool[i] for i in sorted(chosen)]


def verify_episodes(
    output_dir: str | Path,
    experiment: Experiment | None = None,
    count: int = 1,
    kinds: Sequence[str] = (),
    keys: Sequence[str] = (),
    seed: int = 0,
    methods: Sequence[str] = (),
) -> list[Verdict]:
    """Drive again episodes of the store in ``output_dir`` (those of the latest run, or all of
    ``experiment``'s; chosen by :func:`pick_episodes`) and compare each with its stored result."""
    plan, rows = stored_episodes(output_dir, experiment)
    tasks = {t.key: t for t in plan.tasks()}
    here = current_platform().id
    verdicts = []
    chosen = pick_episodes([r for r in rows if r.key in tasks], count, kinds, keys, seed, methods)
    for row in chosen:
        task = _on_its_map(tasks[row.key], row)
        if task.episode.latency.mode == "measured":
            reason = "its latency is the measured computation time, which follows the machine"
            verdicts.append(
                Verdict(row=row, same=None, differences=(reason,), platform=here, wall_s=0)
            )
            continue
        t = time.perf_counter()
        [outcome] = run_job((task,))
        if outcome.result is None:
            raise StoreError(f"episode {row.key} raised when driven again:\n{outcome.error}")
        differences = compare(row, outcome.result, Path(output_dir))
        verdicts.append(
            Verdict(
                row=row,
                same=not differences,
                differences=differences,
                platform=here,
                wall_s=time.perf_counter() - t,
            )
        )
    return verdicts


def _on_its_map(task: EpisodeTask, row: EpisodeRow) -> EpisodeTask:
    """The task with the map it was driven with (it must still be in the cache)."""
    map_dir = row.config.get("map_dir")
    if not map_dir:
        return task
    if not (Path(map_dir) / MAP_FILE).is_file():
        raise StoreError(
            f"episode {row.key} was driven on the map {map_dir}, which is no longer there: "
            "run the experiment (it builds its maps again) or restore the cache"
        )
    return dataclasses.replace(task, map_dir=map_dir)


def compare(row: EpisodeRow, result: EpisodeResult, output_dir: Path) -> tuple[str, ...]:
    """What differs between a stored episode and ``result``, the same episode driven again
    (empty: the same to the last digit, measured times aside)."""
    assert row.metrics is not None  # a finished episode
    out = _metric_differences(
        dataclasses.asdict(row.metrics), dataclasses.asdict(episode_metrics(result))
    )
    stored = read_episode_table(output_dir, row.key, "trajectory")
    again = {
        f.name: getattr(result.trajectory, f.name) for f in dataclasses.fields(result.trajectory)
    }
    out += _first_difference("trajectory step", stored, again, stored.get("time_s"))
    if result.localizations:
        stored = read_episode_table(output_dir, row.key, "localizations")
        columns = localization_columns(result.localizations)
        again = {k: v for k, v in columns.items() if k not in _TIMING_COLUMNS}
        stored = {k: v for k, v in stored.items() if k not in _TIMING_COLUMNS}
        out += _first_difference("localization", stored, again, stored.get("time_s"))
    return tuple(out)


def _metric_differences(stored: dict[str, Any], again: dict[str, Any]) -> list[str]:
    # the declared metrics beside the fields (``extra``), each by its name
    stored, again = (
        {**{k: v for k, v in m.items() if k != "extra"}, **m["extra"]} for m in (stored, again)
    )
    out = []
    for name in sorted(stored.keys() | again.keys()):
        if name.startswith(_TIMING_METRICS):
            continue
        a, b = stored.get(name), again.get(name)
        if not _equal(a, b):
            out.append(f"{name} {_short(a)} -> {_short(b)}")
    return out


def _first_difference(
    what: str, stored: dict[str, Any], again: dict[str, Any], times: Any
) -> list[str]:
    """The first row at which any column differs, with its stored and its new value."""
    if set(stored) != set(again):
        return [f"{what} columns {sorted(set(stored) ^ set(again))} stored or driven only"]
    n_stored, n_again = (len(next(iter(t.values()))) if t else 0 for t in (stored, again))
    for i in range(min(n_stored, n_again)):
        for name in sorted(stored):
            a, b = stored[name][i], again[name][i]
            if not _equal(a, b):
                at = f" (t = {float(times[i]):.2f} s)" if times is not None else ""
                return [f"{what} {i}{at} first differs, in {name}: {_short(a)} -> {_short(b)}"]
    if n_stored != n_again:
        return [f"{what}s: {n_stored} stored, {n_again} driven again"]
    return []


def _plain(value: Any) -> Any:
    """A table cell as plain Python (arrays and tuples as lists)."""
    if isinstance(value, np.ndarray | list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _equal(a: Any, b: Any) -> bool:
    """Equal to the last digit; NaN equals NaN (stored as null, read back as NaN)."""
    a, b = _plain(a), _plain(b)
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    nan = (a is None and isinstance(b, float) and math.isnan(b)) or (
        b is None and isinstance(a, float) and math.isnan(a)
    )
    return a == b or nan


def _short(value: Any) -> str:
    text = repr(_plain(value))
    return text if len(text) <= 60 else text[:57] + "..."
