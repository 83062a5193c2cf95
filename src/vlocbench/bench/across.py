"""Results across towns (pure; no I/O): does a method's failure rate, and the ranking of methods,
hold from town to town?

Over the towns of a run (built-in, generated or hidden), for each (method, setup): the mean over
towns of each town's F, with two intervals: over towns (a bootstrap that draws towns: how much the
town matters) and over repetitions (a bootstrap that draws repetitions within every town: how much
the drives' noise matters); the same for T1 recall. For each setup, the methods (the odometry line
among them) ranked by their mean F across towns, and Kendall's tau-b between that ranking and each
town's own: 1 where a town ranks the methods alike, -1 where it reverses them.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from vlocbench.bench.metrics import bootstrap_means, percentile_interval
from vlocbench.bench.summary import Summary

RESAMPLES = 2000


@dataclass(frozen=True, kw_only=True)
class AcrossTowns:
    """One (method, setup) over ``towns`` towns; F in failures/km, recall as a share."""

    method: str
    setup: str
    towns: int
    failure_mean: float  # mean over towns of each town's F
    failure_towns: tuple[float, float]  # 95 % interval, towns drawn
    failure_repetitions: tuple[float, float]  # 95 % interval, repetitions drawn within each town
    recall_t1: float  # mean over towns of T1 recall (0.25 m, 2 deg; 6-DoF), NaN without recall
    recall_towns: tuple[float, float]  # 95 % interval, towns drawn


@dataclass(frozen=True, kw_only=True)
class RankAgreement:
    """How alike the towns rank the methods in one setup."""

    setup: str
    order: tuple[str, ...]  # methods by their mean F across towns, fewest failures first
    means: tuple[float, ...]  # their mean F across towns, in that order
    tau_by_town: dict[str, float]  # Kendall's tau-b, town's ranking against ``order`` (NaN: ties)

    def ranking(self, label: Callable[[str], str] = str) -> str:
        """``a < b = c``: the order, ties shown as such (each method as ``label`` names it)."""
        text = label(self.order[0])
        for k in range(1, len(self.order)):
            text += (" = " if self.means[k] == self.means[k - 1] else " < ") + label(self.order[k])
        return text

    @property
    def same_everywhere(self) -> bool:
        """Every town ranks the methods as the towns together do."""
        return all(t == 1.0 for t in self.tau_by_town.values())

    @property
    def tau_min(self) -> float:
        return min(self.tau_by_town.values(), default=float("nan"))


def kendall_tau_b(x: Sequence[float], y: Sequence[float]) -> float:
    """Kendall's tau-b of two scorings of the same items (ties counted as tau-b does); NaN when
    either scores every item alike."""
    concordant = discordant = ties_x = ties_y = 0
    for i, j in itertools.combinations(range(len(x)), 2):
        dx, dy = np.sign(x[i] - x[j]), np.sign(y[i] - y[j])
        if dx == 0 and dy == 0:
            continue
        if dx == 0:
            ties_x += 1
        elif dy == 0:
            ties_y += 1
        elif dx == dy:
            concordant += 1
        else:
            discordant += 1
    n_x = concordant + discordant + ties_x
    n_y = concordant + discordant + ties_y
    if n_x == 0 or n_y == 0:
        return float("nan")
    return float((concordant - discordant) / np.sqrt(n_x * n_y))


def _over_towns(values: Sequence[float], rng: np.random.Generator) -> tuple[float, float]:
    return percentile_interval(bootstrap_means(values, rng, RESAMPLES))


def _over_repetitions(
    per_town: Sequence[Sequence[float]], rng: np.random.Generator
) -> tuple[float, float]:
    """The mean over towns with each town's repetitions drawn again."""
    town_means = [bootstrap_means(r, rng, RESAMPLES) for r in per_town]
    return percentile_interval(np.mean(town_means, axis=0))


def across_towns(summary: Summary, seed: int = 0) -> list[AcrossTowns]:
    """Each (method, setup) with failure episodes in every town of the run (fewer towns would mix
    towns into the mean differently from method to method)."""
    out = []
    for method in summary.methods:
        for setup in summary.setups:
            cells = [summary.cell(t, method, setup.label) for t in summary.towns]
            if any(c is None or c.failure is None for c in cells):
                continue
            rng = np.random.default_rng(seed)
            f = [c.failure for c in cells if c is not None and c.failure is not None]
            t1 = [c.recall[0] for c in cells if c is not None and c.recall]
            has_recall = len(t1) == len(cells)
            out.append(
                AcrossTowns(
                    method=method,
                    setup=setup.label,
                    towns=len(cells),
                    failure_mean=float(np.mean([x.mean for x in f])),
                    failure_towns=_over_towns([x.mean for x in f], rng),
                    failure_repetitions=_over_repetitions([x.per_repetition for x in f], rng),
                    recall_t1=float(np.mean(t1)) if has_recall else float("nan"),
                    recall_towns=_over_towns(t1, rng) if has_recall else (np.nan, np.nan),
                )
            )
    return out


def rank_agreement(summary: Summary, rows: Sequence[AcrossTowns]) -> list[RankAgreement]:
    """Per setup with at least two methods across all towns: the ranking across towns and each
    town's tau-b against it."""
    out = []
    for setup in summary.setups:
        here = [r for r in rows if r.setup == setup.label]
        if len(here) < 2:
            continue
        methods = [r.method for r in here]
        pooled = [r.failure_mean for r in here]
        tau = {
            summary.town_names[town]: kendall_tau_b(
                [summary.failure_mean(town, m, setup.label) for m in methods], pooled
            )
            for town in summary.towns
        }
        ranked = sorted(zip(pooled, methods), key=lambda p: p[0])
        out.append(
            RankAgreement(
                setup=setup.label,
                order=tuple(m for _, m in ranked),
                means=tuple(f for f, _ in ranked),
                tau_by_town=tau,
            )
        )
    return out


__all__ = ["AcrossTowns", "RankAgreement", "across_towns", "kendall_tau_b", "rank_agreement"]
