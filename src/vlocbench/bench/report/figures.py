"""The report's figures (PNG, matplotlib's Agg): failure rate against the swept level with the
odometry line, beside the paper's published curves (F, and T1 recall against the light), failure
rate against recall (the paper's Fig. 5), failure sites on the town map (its
Fig. 6), computation time per method."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from vlocbench.bench.consistency import ConfidenceCurve
from vlocbench.bench.metrics import FailureRate
from vlocbench.bench.paper import paper_results
from vlocbench.bench.report.comparison import level_text, ours_per_setup, paper_axis
from vlocbench.bench.report.tables import level_header, method_label, setup_header
from vlocbench.bench.requirements import MeasuredAccuracy, OracleSweep
from vlocbench.bench.summary import BASELINE, Summary

# the paper's methods in muted tones, so that ours stand out in the same axes
PAPER_COLORS = (
    "#9ecae1",
    "#fdae6b",
    "#a1d99b",
    "#bcbddc",
    "#fc9272",
    "#c7c7c7",
    "#dadaeb",
    "#9edae5",
)
# one marker and line style per line of a method: the levels of the swept keys after the first
MARKERS = "os^Dv<>p"
LINE_STYLES = ("-", ":", "-.", (0, (5, 1)))
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")


@dataclass(frozen=True)
class Series:
    """The failure figure's x axis and its lines. ``x``, ``ticks``: (X,); ``lines``: per
    combination of the swept keys after the first, its legend text ("" for one line) and the
    setup label at each x (None where the sweep has no such setup)."""

    x: list[float]
    ticks: list[str]
    xlabel: str
    lines: list[tuple[str, list[str | None]]]


def figure_series(summary: Summary) -> Series:
    """A numeric first swept key is the x axis, a line per combination of the other keys' levels
    (F against k with the filter's settings beside each other); otherwise each setup is a tick of
    one line."""
    setups = summary.setups
    first = [s.levels[0][1] for s in setups if s.levels]
    if len(first) < len(setups) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in first
    ):
        ticks = [setup_header(summary, s.label) for s in setups]
        return Series(
            list(range(len(setups))),
            ticks,
            ", ".join(summary.axis) or "setup",
            [("", [s.label for s in setups])],
        )
    x = list(dict.fromkeys(float(v) for v in first))
    lines: dict[str, list[str | None]] = {}
    for setup, value in zip(setups, first):
        rest = "; ".join(level_header(k, v) for k, v in setup.levels[1:])
        lines.setdefault(rest, [None] * len(x))[x.index(float(value))] = setup.label
    return Series(x, [f"{v:g}" for v in x], summary.axis[0], list(lines.items()))


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def failure_figure(summary: Summary, town: str, path: Path) -> Path:
    series = figure_series(summary)
    x, ticks = np.array(series.x), series.ticks
    # the lines of one method a little apart, so that their intervals do not hide each other
    step = np.diff(x).min() if len(x) > 1 else 1.0
    shift = 0.06 * step * (np.arange(len(series.lines)) - (len(series.lines) - 1) / 2)
    fig, ax = plt.subplots(figsize=(7, 4))
    for method, color in zip(summary.methods, COLORS * 4):
        for k, ((rest, labels), dx) in enumerate(zip(series.lines, shift)):
            marker = MARKERS[k % len(MARKERS)]
            cells = [summary.cell(town, method, lab) if lab else None for lab in labels]
            f = [c.failure if c else None for c in cells]
            mean = np.array([v.mean if v else np.nan for v in f])
            low = np.array([v.low if v else np.nan for v in f])
            high = np.array([v.high if v else np.nan for v in f])
            name = method_label(method) + (f" ({rest})" if rest else "")
            if method == BASELINE:
                ax.plot(
                    x + dx, mean, "--", marker=marker if rest else None, color="0.4", label=name
                )
                continue
            ax.errorbar(
                x + dx,
                mean,
                yerr=[mean - low, high - mean],
                marker=marker,
                linestyle=LINE_STYLES[k % len(LINE_STYLES)],
                color=color,
                capsize=3,
                label=name,
            )
    ax.set_xticks(
        x, ticks, rotation=30 if len(ticks) > 6 else 0, ha="right" if len(ticks) > 6 else "center"
    )
    ax.set_xlabel(series.xlabel)
    ax.set_ylabel("failure rate F (1/km)")
    ax.set_ylim(bottom=0)
    ax.set_title(f"{summary.town_names[town]}: failure rate (95 % CI)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def _paper_curves(
    ax: plt.Axes,
    x: Sequence[float] | np.ndarray,
    curves: Mapping[str, Sequence[float]],
    ours: Sequence[str],
) -> None:
    """The paper's methods dashed, those with the local features of one of ours stand out."""
    named = " ".join(ours).lower()
    for (method, values), color in zip(curves.items(), PAPER_COLORS * 4):
        same = method.split(" + ")[-1].lower() in named
        ax.plot(
            x,
            values,
            "--",
            color=color,
            lw=2.0 if same else 1.0,
            alpha=1.0 if same else 0.6,
            label=f"paper: {method}",
        )


def _finish_beside(ax: plt.Axes, title: str) -> None:
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))


def paper_failure_figure(summary: Summary, town: str, path: Path) -> Path | None:
    """F against the paper's levels: ours (solid, 95 % intervals) and the paper's published curves
    (dashed) in the same axes, with both odometry lines; None when the run sweeps no factor of the
    paper or the paper has no table for this town. The x axis is the paper's levels in order."""
    found = paper_axis(summary)
    name = summary.town_names[town]
    if found is None or name not in found[0].failure_rate:
        return None
    table, ours_levels = found
    paper = paper_results()
    x = np.arange(len(table.levels))
    fig, ax = plt.subplots(figsize=(9.5, 4.2))
    _paper_curves(ax, x, table.failure_rate[name], summary.methods)
    ax.axhline(
        paper.odometry_failure_rate[name], ls=":", color="0.5", lw=1.2, label="paper: odometry only"
    )
    at = [table.levels.index(lv) if lv in table.levels else None for lv in ours_levels]
    for method, color in zip(summary.methods, COLORS * 4):
        pts = []
        for s, i in zip(summary.setups, at):
            c = summary.cell(town, method, s.label)
            if i is not None and c is not None and c.failure is not None:
                pts.append((i, c.failure.mean, c.failure.low, c.failure.high))
        if not pts:
            continue
        level, mean, low, high = (np.array(v) for v in zip(*sorted(pts)))
        if method == BASELINE:
            ax.axhline(float(np.mean(mean)), ls="-", color="0.3", lw=1.5, label="odometry only")
            continue
        ax.errorbar(
            level,
            mean,
            yerr=[mean - low, high - mean],
            fmt="o-",
            color=color,
            lw=2,
            capsize=3,
            label=method,
        )
    ax.set_xticks(
        x,
        [level_text(lv) for lv in table.levels],
        rotation=30 if len(x) > 6 else 0,
        ha="right" if len(x) > 6 else "center",
    )
    ax.set_xlabel(
        {
            "illumination": "illumination level k",
            "viewpoint": "camera (z m, pitch deg)",
            "weather": "fog visual range v (m)",
        }.get(table.factor, table.factor)
    )
    ax.set_ylabel("failure rate F (1/km)")
    ax.set_ylim(bottom=0)
    _finish_beside(ax, f"{name}: failure rate, vlocbench (solid) and the paper (dashed)")
    return _save(fig, path)


def paper_recall_figure(summary: Summary, town: str, path: Path) -> Path | None:
    """T1 recall of the ground-truth drives against the illumination level k: ours (solid, every
    level the run has) and the paper's Table 5 (dashed, its levels 0, 2, ..., 10); None when the
    run does not sweep k, has no recall drive in this town, or the paper has no table for it."""
    found = paper_axis(summary)
    name = summary.town_names[town]
    if found is None or name not in found[0].recall_t1:
        return None
    table, ours_levels = found
    ours = {}
    for method in (m for m in summary.methods if m != BASELINE):
        t1 = ours_per_setup(summary, town, method)[1]
        pts = sorted((lv, v) for lv, v in zip(ours_levels, t1) if lv is not None and np.isfinite(v))
        if pts:
            ours[method] = pts
    if not ours:
        return None
    fig, ax = plt.subplots(figsize=(9.5, 4.2))
    _paper_curves(ax, table.recall_levels, table.recall_t1[name], summary.methods)
    for (method, pts), color in zip(ours.items(), COLORS * 4):
        ax.plot(*zip(*pts), "o-", color=color, lw=2, label=method)
    ax.set_xticks(sorted({*table.recall_levels, *(lv for p in ours.values() for lv, _ in p)}))
    ax.set_xlabel("illumination level k")
    ax.set_ylabel("T1 recall (%), (0.25 m, 2 deg)")
    ax.set_ylim(0, 101)
    _finish_beside(ax, f"{name}: T1 recall, vlocbench (solid) and the paper (dashed)")
    return _save(fig, path)


def failure_vs_recall_figure(summary: Summary, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(6, 4.5))
    markers = "osD^v<>"
    for method, color in zip(summary.methods, COLORS * 4):
        if method == BASELINE:
            continue
        for town, marker in zip(summary.towns, markers * 4):
            pts = [
                (100 * c.recall[0], c.failure.mean)
                for s in summary.setups
                if (c := summary.cell(town, method, s.label)) and c.recall and c.failure
            ]
            if pts:
                r, f = zip(*pts)
                label = (
                    method if len(summary.towns) == 1 else f"{method}, {summary.town_names[town]}"
                )
                ax.scatter(r, f, color=color, marker=marker, label=label)
    ax.set_xlabel("recall at (0.25 m, 2°), %")
    ax.set_ylabel("failure rate F (1/km)")
    ax.set_xlim(0, 100)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    if ax.collections:
        ax.legend(fontsize=8)
    else:  # no setup has both recall and failure episodes yet
        ax.text(50, 0.5, "no setup with both recall and failure episodes", ha="center")
    ax.set_title("failure rate against recall")
    return _save(fig, path)


def crash_sites_figure(summary: Summary, town: str, town_obj: Any, path: Path) -> Path:
    from vlocbench.sim.birdseye import town_map_figure

    fig = town_map_figure(town_obj, route=True)
    ax = fig.axes[0]
    for method, color in zip(summary.methods, COLORS * 4):
        cells = {c.keys: c for s in summary.setups if (c := summary.cell(town, method, s.label))}
        xy = [p for c in cells.values() for p in c.sites_xy]  # shared baselines counted once
        if not xy:
            continue
        xs, ys = zip(*xy)
        if method == BASELINE:
            ax.scatter(
                xs, ys, marker=".", s=18, c="0.35", zorder=9, label=f"odometry only ({len(xy)})"
            )
        else:
            ax.scatter(xs, ys, marker="x", s=36, c=color, zorder=10, label=f"{method} ({len(xy)})")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title(f"{summary.town_names[town]}: failure sites, all setups and repetitions")
    return _save(fig, path)


def confidence_figure(
    summary: Summary, town: str, curves: Mapping[tuple[str, str, str], ConfidenceCurve], path: Path
) -> Path:
    """Precision against the share of queries answered, answers most confident first: a line per
    method (colour) and setup (lighter as the level gets harder)."""
    fig, ax = plt.subplots(figsize=(7, 4.2))
    methods = [m for m in summary.methods if m != BASELINE]
    n = len(summary.setups)
    for method, color in zip(methods, COLORS * 4):
        for k, s in enumerate(summary.setups):
            curve = curves.get((town, method, s.label))
            if curve is None or not len(curve.share):
                continue
            label = f"{method}, {setup_header(summary, s.label)}"
            alpha = 1.0 - 0.75 * k / max(n - 1, 1)
            ax.step(
                curve.share, curve.precision, where="post", color=color, alpha=alpha, label=label
            )
    ax.axhline(0.95, color="0.5", lw=0.8, ls=":")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("share of queries answered (most confident first)")
    ax.set_ylabel("precision: share within (5 m, 10°)")
    ax.set_title(f"{summary.town_names[town]}: can the answers' confidence be trusted?")
    if ax.lines[1:]:
        ax.legend(fontsize=7, loc="lower left", ncol=2)
    return _save(fig, path)


def requirements_figure(
    summary: Summary,
    town: str,
    sweeps: Sequence[OracleSweep],
    placed: Sequence[tuple[str, MeasuredAccuracy, FailureRate]],
    path: Path,
) -> Path:
    """F against the oracle's position sigma (its 95 % interval shaded), the odometry line, and
    each real method at the sigma its answers measured, labelled with its answer rate and far
    answers."""
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for sweep, color in zip(sweeps, ("0.15", "0.45")):
        mean = [f.mean for f in sweep.failure]
        ax.plot(sweep.sigmas_m, mean, "o-", color=color, label=f"{sweep.method} (swept)")
        low, high = [f.low for f in sweep.failure], [f.high for f in sweep.failure]
        ax.fill_between(sweep.sigmas_m, low, high, color=color, alpha=0.15, lw=0)
    odometry = next(
        (
            c.failure
            for s in summary.setups
            if (c := summary.cell(town, BASELINE, s.label)) and c.failure
        ),
        None,
    )
    if odometry is not None:
        ax.axhline(odometry.mean, ls="--", color="0.4", lw=1, label="odometry only")
    for (name, acc, f), color in zip(placed, COLORS * 4):
        x = max(acc.equivalent_sigma_m, 0.01) if np.isfinite(acc.equivalent_sigma_m) else np.nan
        ax.errorbar(
            [x],
            [f.mean],
            yerr=[[f.mean - f.low], [f.high - f.mean]],
            fmt="D",
            color=color,
            capsize=3,
            label=f"{name}: {100 * acc.answer_rate:.0f} % answered, "
            f"{100 * acc.far_share:.0f} % beyond 5 m",
        )
    ax.set_xscale("symlog", linthresh=0.25)
    swept = sorted({x for sweep in sweeps for x in sweep.sigmas_m})
    ax.set_xticks(swept, [f"{x:g}" for x in swept])
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("oracle position sigma (m); a method at the sigma with its answers' median error")
    ax.set_ylabel("failure rate F (1/km)")
    ax.set_title(f"{summary.town_names[town]}: how accurate must localization be?")
    ax.legend(fontsize=7)
    return _save(fig, path)


def computation_time_figure(summary: Summary, path: Path) -> Path:
    methods = [m for m in summary.methods if m != BASELINE]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    width = 0.8 / max(1, len(summary.towns))
    for k, town in enumerate(summary.towns):
        ct = []
        for m in methods:
            values = [c.ct_s for s in summary.setups if (c := summary.cell(town, m, s.label))]
            finite = [v for v in values if np.isfinite(v)]
            ct.append(1000 * float(np.mean(finite)) if finite else 0.0)
        ax.bar(np.arange(len(methods)) + k * width, ct, width, label=summary.town_names[town])
    ax.set_xticks(np.arange(len(methods)) + width * (len(summary.towns) - 1) / 2, methods)
    ax.set_ylabel("computation time per query (ms)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)
