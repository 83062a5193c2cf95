"""The paper's published results, and the shape measures that put a run beside them (pure).

``data/paper_results.yaml`` holds Tables 2-5 of Suomela et al. (WACV 2023). A run is compared with
the table of its swept factor (``illumination.k``: Tables 2 and 5, ``viewpoint``: Table 3,
``weather``: Table 4) by measures that do not need the two systems to agree level by level:

- F at the easiest level (the first);
- the rank correlation (Spearman) of F with the level: does F rise as conditions get harder?
- the first level at which F reaches the odometry-only line;
- the highest T1 recall at which F still exceeds the odometry-only line (the paper: navigation
  gains from localization only above about 60 % T1 recall in Town01).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np
import yaml

from vlocbench.interfaces import Array

FACTOR_OF_AXIS = {"illumination.k": "illumination", "viewpoint": "viewpoint", "weather": "weather"}


@dataclass(frozen=True)
class PaperTable:
    """One of the paper's failure-rate tables: ``levels`` and F per method and town."""

    factor: str
    levels: tuple[Any, ...]
    failure_rate: dict[str, dict[str, tuple[float, ...]]]  # town -> method -> F per level
    recall_levels: tuple[Any, ...]  # illumination only: the levels of Table 5
    recall_t1: dict[str, dict[str, tuple[float, ...]]]  # town -> method -> T1 % per level


@dataclass(frozen=True)
class PaperResults:
    citation: str
    methods: tuple[str, ...]
    odometry_failure_rate: dict[str, float]
    computation_time_ms: dict[str, float]
    tables: dict[str, PaperTable]  # by factor


@functools.cache
def paper_results() -> PaperResults:
    """The paper's Tables 2-5, shipped with the package."""
    text = (resources.files("vlocbench.bench") / "data" / "paper_results.yaml").read_text()
    d = yaml.safe_load(text)

    def by_town(block: dict[str, Any], pick: Any = None) -> dict[str, dict[str, tuple]]:
        return {
            town: {m: tuple(v if pick is None else pick(v)) for m, v in rows.items()}
            for town, rows in block.items()
            if town != "levels"
        }

    recall = d["illumination_recall"]
    tables = {}
    for factor in ("illumination", "viewpoint", "weather"):
        block = d[factor]
        with_recall = factor == "illumination"
        tables[factor] = PaperTable(
            factor=factor,
            levels=tuple(tuple(v) if isinstance(v, list) else v for v in block["levels"]),
            failure_rate=by_town(block),
            recall_levels=tuple(recall["levels"]) if with_recall else (),
            recall_t1=by_town(recall, lambda rows: [r[0] for r in rows]) if with_recall else {},
        )
    return PaperResults(
        citation=d["citation"],
        methods=tuple(d["methods"]),
        odometry_failure_rate=dict(d["odometry_failure_rate"]),
        computation_time_ms=dict(zip(d["methods"], d["computation_time_ms"])),
        tables=tables,
    )


def spearman(x: Sequence[float] | Array, y: Sequence[float] | Array) -> float:
    """Spearman's rank correlation (ties share their mean rank); NaN when either is constant or
    fewer than 3 points."""
    a, b = np.asarray(x, np.float64), np.asarray(y, np.float64)
    if len(a) < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return float("nan")
    ra, rb = _ranks(a), _ranks(b)
    return float(np.corrcoef(ra, rb)[0, 1])


def _ranks(v: np.ndarray) -> np.ndarray:
    order = np.argsort(v, kind="stable")
    ranks = np.empty(len(v))
    ranks[order] = np.arange(len(v), dtype=np.float64)
    for value in np.unique(v):  # ties: the mean of their ranks
        tie = v == value
        ranks[tie] = ranks[tie].mean()
    return ranks


@dataclass(frozen=True)
class Shape:
    """How a method's F follows the difficulty: see the module docstring."""

    f_easiest: float
    rank_correlation: float
    odometry_level: int | None  # index of the first level with F >= the odometry line
    worse_than_odometry_below_t1: float  # % (NaN: F never exceeds the line where recall is known)


def shape(
    failure_rate: Sequence[float],
    odometry: float,
    level_rank: Sequence[float] | None = None,
    recall_t1: Sequence[float] | None = None,
) -> Shape:
    """Shape measures of F over levels in order of difficulty (``level_rank``: a number per level
    that grows with difficulty; default: the order given). ``recall_t1`` (%, per level, NaN where
    unknown) for the recall crossover."""
    f = np.asarray(failure_rate, np.float64)
    rank = np.arange(len(f), dtype=np.float64) if level_rank is None else np.asarray(level_rank)
    finite = np.isfinite(f)
    above = np.flatnonzero(finite & (f >= odometry))
    crossover = float("nan")
    if recall_t1 is not None:
        r = np.asarray(recall_t1, np.float64)
        worse = finite & np.isfinite(r) & (f > odometry)
        crossover = float(r[worse].max()) if worse.any() else float("nan")
    return Shape(
        f_easiest=float(f[0]) if len(f) else float("nan"),
        rank_correlation=spearman(rank[finite], f[finite]),
        odometry_level=int(above[0]) if len(above) else None,
        worse_than_odometry_below_t1=crossover,
    )
