"""The accuracy navigation needs (pure; no I/O): the oracle's error swept against the failure rate,
and each real method placed on the same axes by what its answers measured.

A real method's answers are not Gaussian (most are close, some confidently far off), so it is
placed by the oracle's sigma with the same median planar position error (for the oracle's
isotropic Gaussian noise the median error is sigma * sqrt(2 ln 2)), with its answer rate and the
share of its answers beyond 5 m beside it: a method whose F lies above the oracle's curve at its
place loses more to its wrong answers and its gaps than to its typical error.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from vlocbench.bench.methods import MethodSpec
from vlocbench.bench.metrics import FailureRate
from vlocbench.bench.records import WRONG_THRESHOLD
from vlocbench.bench.summary import BASELINE, Summary

RAYLEIGH_MEDIAN = float(np.sqrt(2 * np.log(2)))  # median / sigma of a 2D Gaussian's distance
FAR_M = WRONG_THRESHOLD[0]  # an answer this far off is wrong, whatever its rotation


@dataclass(frozen=True)
class MeasuredAccuracy:
    """What a ground-truth drive's answers measured: the oracle sigma (m) with their median planar
    position error, the share of queries answered, and the share of answers beyond 5 m."""

    equivalent_sigma_m: float
    answer_rate: float
    far_share: float


def measured_accuracy(locs: Mapping[str, Any]) -> MeasuredAccuracy:
    """From one drive's localization records (columns, as stored)."""
    ok = np.asarray(locs.get("success", []), bool)
    if not ok.any():
        return MeasuredAccuracy(np.nan, 0.0 if len(ok) else np.nan, np.nan)
    err = np.asarray(locs["position_error_m"], np.float64)[ok]
    return MeasuredAccuracy(
        float(np.median(err) / RAYLEIGH_MEDIAN), float(ok.mean()), float(np.mean(err > FAR_M))
    )


def oracle_sigma_m(method: MethodSpec) -> float | None:
    """The position sigma (m) of an ``oracle`` method; None for any other kind."""
    return float(method.args.get("position_sigma_m", 0.0)) if method.kind == "oracle" else None


def oracle_at(sigmas_m: list[float], failures: list[float], sigma_m: float) -> float:
    """The oracle's F at ``sigma_m``, linear between the swept sigmas (NaN outside them)."""
    order = np.argsort(sigmas_m)
    xs, ys = np.asarray(sigmas_m)[order], np.asarray(failures)[order]
    if not len(xs) or not np.isfinite(sigma_m) or not xs[0] <= sigma_m <= xs[-1]:
        return float("nan")
    return float(np.interp(sigma_m, xs, ys))


@dataclass(frozen=True)
class OracleSweep:
    """An oracle method's failure rate over the swept sigmas of one town (sorted by sigma)."""

    method: str
    sigmas_m: list[float]
    failure: list[FailureRate]

    def at(self, sigma_m: float) -> float:
        return oracle_at(self.sigmas_m, [f.mean for f in self.failure], sigma_m)


def oracle_sweeps(summary: Summary, town: str) -> list[OracleSweep]:
    """Each oracle method whose sigma takes more than one value over the setups."""
    out = []
    for name in summary.methods:
        points = []
        for setup in summary.setups:
            method = next((m for m in summary.plan.methods_of(setup) if m.name == name), None)
            sigma = oracle_sigma_m(method) if method is not None else None
            cell = summary.cell(town, name, setup.label)
            if sigma is not None and cell is not None and cell.failure is not None:
                points.append((sigma, cell.failure))
        if len({s for s, _ in points}) > 1:
            points.sort(key=lambda p: p[0])
            out.append(OracleSweep(name, [s for s, _ in points], [f for _, f in points]))
    return out


def placed_methods(
    summary: Summary, town: str, accuracy: Mapping[tuple[str, str, str], MeasuredAccuracy]
) -> list[tuple[str, MeasuredAccuracy, FailureRate]]:
    """The methods that are no oracle, each with its measured accuracy and F (of the first setup
    that has both: a swept oracle leaves the other methods' episodes the same in every setup)."""
    oracles = {m.name for m in summary.spec.methods if m.kind == "oracle"}
    out = []
    for name in (m for m in summary.methods if m not in oracles and m != BASELINE):
        for setup in summary.setups:
            cell, acc = (
                summary.cell(town, name, setup.label),
                accuracy.get((town, name, setup.label)),
            )
            if cell is not None and cell.failure is not None and acc is not None:
                out.append((name, acc, cell.failure))
                break
    return out
