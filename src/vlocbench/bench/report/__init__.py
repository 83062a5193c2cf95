"""Reports of a run: the paper's tables (Markdown and LaTeX), figures (PNG) and one self-contained
HTML page, written to ``OUTPUT/report/``; a package by part: :mod:`.tables`, :mod:`.comparison`
(beside the paper), :mod:`.figures` and :mod:`.page`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from vlocbench.bench.across import across_towns, rank_agreement
from vlocbench.bench.consistency import confidence_curve
from vlocbench.bench.metrics import METRICS
from vlocbench.bench.platform import read_platform_file
from vlocbench.bench.report.comparison import paper_comparison_tables
from vlocbench.bench.report.figures import (
    computation_time_figure,
    confidence_figure,
    crash_sites_figure,
    failure_figure,
    failure_vs_recall_figure,
    paper_failure_figure,
    paper_recall_figure,
    requirements_figure,
)
from vlocbench.bench.report.page import write_page
from vlocbench.bench.report.tables import (
    Curves,
    Table,
    across_towns_table,
    cause_table,
    confidence_table,
    declared_metrics_table,
    drift_table,
    failure_table,
    fragmentation_table,
    latex,
    markdown,
    not_stored_line,
    per_town_table,
    place_recall_table,
    planned_repetitions,
    platforms_line,
    ranking_table,
    recall_table,
    requirements_table,
    verdict_table,
)
from vlocbench.bench.requirements import (
    MeasuredAccuracy,
    measured_accuracy,
    oracle_sweeps,
    placed_methods,
)
from vlocbench.bench.runs import Experiment, stored_episodes
from vlocbench.bench.store import EpisodeRow, StoreError, read_episode_table, read_platforms
from vlocbench.bench.summary import BASELINE, Summary, summarize

REPORT_DIR = "report"
__all__ = [
    "REPORT_DIR",
    "ReportFiles",
    "not_stored_line",
    "paper_comparison_tables",
    "platforms_line",
    "summary_lines",
    "write_report",
]


@dataclass(frozen=True)
class ReportFiles:
    html: Path
    markdown: Path
    latex: Path
    figures: tuple[Path, ...]
    summary: Summary
    platforms: str  # platforms_line: which platforms the episodes ran on ('' if not recorded)


@dataclass(frozen=True)
class DriveFigures:
    """What the report reads from each (town, method, setup)'s ground-truth drive's stored
    localizations: its confidence curve and its measured accuracy."""

    curves: Curves
    accuracy: dict[tuple[str, str, str], MeasuredAccuracy]


def drive_figures(summary: Summary, rows: Sequence[EpisodeRow], output_dir: Path) -> DriveFigures:
    """From the stored tables (a drive without one is left out)."""
    recall = {r.key for r in rows if r.kind == "recall" and r.status == "ok"}
    curves, accuracy = {}, {}
    for cell_key, cell in summary.cells.items():
        for key in sorted(cell.keys & recall):
            try:
                locs = read_episode_table(output_dir, key, "localizations")
            except StoreError:
                continue
            curves[cell_key] = confidence_curve(locs)
            accuracy[cell_key] = measured_accuracy(locs)
    return DriveFigures(curves, accuracy)


def report_tables(summary: Summary, drives: DriveFigures | None = None) -> list[tuple[str, Table]]:
    out = []
    curves = drives.curves if drives else {}
    odometry_runs = (
        f", odometry only over {planned_repetitions(summary, BASELINE)}"
        if summary.spec.baseline
        else ""
    )
    for town in summary.towns:
        name = summary.town_names[town]
        sweeps = oracle_sweeps(summary, town)
        if sweeps and drives:
            out.append(
                (
                    f"{name}: how accurate must localization be? Each method at the oracle sigma "
                    "with its answers' median planar error (ground-truth drive), its F (failures/km, "
                    "[bootstrap 95 % CI]) and the swept oracle's F at that sigma",
                    requirements_table(sweeps, placed_methods(summary, town, drives.accuracy)),
                )
            )
        if summary.spec.methods and summary.spec.baseline and len(summary.axis) == 1:
            out.append(
                (
                    f"{name}: verdict, over {summary.axis[0]} from easy to hard (the levels "
                    "with stored failure episodes): how far each method keeps F at most 1 /km, "
                    "and from where it crashes more often than odometry alone",
                    verdict_table(summary, town),
                )
            )
        out.append(
            (
                f"{name}: failure rate F (failures/km, mean [bootstrap 95 % CI] over "
                f"{summary.spec.repetitions} repetitions{odometry_runs}; a cell with fewer "
                "stored gives its count) and computation time per query",
                failure_table(summary, town),
            )
        )
        out.append(
            (
                f"{name}: failure rate by cause (failures/km; the paper counts collisions) "
                "and episodes that ran out of time",
                cause_table(summary, town),
            )
        )
        if any(c.recall is not None for (t, _, _), c in summary.cells.items() if t == town):
            out.append(
                (
                    f"{name}: recall (%) at (0.25 m, 2°) / (0.5 m, 5°) / (5 m, 10°) on 6-DoF "
                    "errors, ground-truth drive, raw localization (share of answers confident "
                    "and wrong: beyond (5 m, 10°))",
                    recall_table(summary, town),
                )
            )
            out.append(
                (
                    f"{name}: place recognition alone, Recall@1 / @5 / @10 (%) of a retrieved "
                    "gallery image within 5, 10 and 25 m, same drive",
                    place_recall_table(summary, town),
                )
            )
            out.append(
                (
                    f"{name}: recall (%) on planar (x, y, yaw) errors, same drive",
                    recall_table(summary, town, "planar"),
                )
            )
            out.append(
                (
                    f"{name}: recall (%) of the fused (EKF) pose at every step, same drive "
                    "(lock losses per km: the EKF reset at the truth)",
                    recall_table(summary, town, "fused"),
                )
            )
        if curves:
            out.append(
                (
                    f"{name}: can the answers' confidence be trusted? Answers of the ground-truth "
                    "drive ranked by confidence: area under precision (within 5 m, 10°) against "
                    "the share of queries answered, and the threshold that keeps precision at 95 %",
                    confidence_table(summary, town, curves),
                )
            )
        if summary.spec.baseline:
            out.append(
                (
                    f"{name}: wheel-odometry drift of the EKF, at the end of each failure-free "
                    "stretch over its length",
                    drift_table(summary, town),
                )
            )
        if METRICS:
            out.append(
                (
                    f"{name}: declared metrics (vlocbench.bench.metrics.METRICS), over the drives "
                    "and repetitions each declares",
                    declared_metrics_table(summary, town),
                )
            )
        out.append(
            (
                f"{name}: where failures happen (25 m stretches of the route) and the "
                "mean tracking error",
                fragmentation_table(summary, town),
            )
        )
    tables = out + towns_tables(summary) + paper_comparison_tables(summary)
    return [(caption, table) for caption, table in tables if table[1]]  # a table without rows


def towns_tables(summary: Summary) -> list[tuple[str, Table]]:
    """Where a run has several towns: them side by side, each method across them, and whether
    they rank the methods alike."""
    if len(summary.towns) < 2:
        return []
    rows = across_towns(summary)
    n = len(summary.towns)
    return [
        (
            "every town: failure rate F (failures/km, mean over repetitions) and T1 recall "
            "(0.25 m, 2°; ground-truth drive)",
            per_town_table(summary),
        ),
        (
            f"across the {n} towns: F and T1 recall, mean over towns, with bootstrap 95 % "
            "intervals drawing towns and drawing repetitions within each town",
            across_towns_table(summary, rows),
        ),
        (
            f"do the {n} towns rank the methods alike? Kendall's tau-b of each town's ranking "
            "by F against the ranking across towns (1: the same order; NaN: a town ties them all)",
            ranking_table(summary, rank_agreement(summary, rows)),
        ),
    ]


def _write_tables(out: Path, tables: list[tuple[str, Table]]) -> tuple[Path, Path]:
    """``tables.md`` and ``tables.tex``."""
    md = out / "tables.md"
    md.write_text("\n\n".join(f"**{caption}**\n\n{markdown(t)}" for caption, t in tables) + "\n")
    tex = out / "tables.tex"
    tex.write_text(
        "% needs \\usepackage{booktabs, graphicx}\n"
        + "\n\n".join(latex(t, c) for c, t in tables)
        + "\n"
    )
    return md, tex


def _write_figures(summary: Summary, out: Path, drives: DriveFigures) -> list[Path]:
    from vlocbench.bench.towns import town_named

    figures: list[Path] = []
    for town in summary.towns:
        name = summary.town_names[town]
        if any(key[0] == town for key in drives.curves):
            path = out / f"confidence_{name}.png"
            figures.append(confidence_figure(summary, town, drives.curves, path))
        if sweeps := oracle_sweeps(summary, town):
            placed = placed_methods(summary, town, drives.accuracy)
            path = out / f"requirements_{name}.png"
            figures.append(requirements_figure(summary, town, sweeps, placed, path))
        figures.append(failure_figure(summary, town, out / f"failure_rate_{name}.png"))
        figures.append(
            crash_sites_figure(summary, town, town_named(town), out / f"failure_sites_{name}.png")
        )
        beside = (
            paper_failure_figure(summary, town, out / f"failure_rate_{name}_paper.png"),
            paper_recall_figure(summary, town, out / f"recall_{name}_paper.png"),
        )
        figures.extend(f for f in beside if f is not None)
    if summary.spec.methods:
        if summary.spec.recall and summary.spec.failure:
            figures.append(failure_vs_recall_figure(summary, out / "failure_vs_recall.png"))
        figures.append(computation_time_figure(summary, out / "computation_time.png"))
    return figures


def write_report(
    output_dir: str | Path, examples: bool = True, plan: Experiment | None = None
) -> ReportFiles:
    """Write the tables, figures and the HTML page of the latest run in ``output_dir``, or of
    ``plan`` (an experiment's plan or file) over every episode of it stored there (run in parts,
    by several runs)."""
    plan, rows = stored_episodes(output_dir, plan)
    summary = summarize(plan, rows)
    out = Path(output_dir) / REPORT_DIR
    out.mkdir(parents=True, exist_ok=True)
    drives = drive_figures(summary, rows, Path(output_dir))
    tables = report_tables(summary, drives)
    md, tex = _write_tables(out, tables)
    figures = _write_figures(summary, out, drives)
    map_dirs = sorted({r.config["map_dir"] for r in rows if r.config.get("map_dir")})
    maps = [read_platform_file(Path(d)) for d in map_dirs]
    platforms = platforms_line(summary, read_platforms(output_dir), maps)
    page = write_page(summary, rows, tables, figures, examples, out, platforms)
    return ReportFiles(page, md, tex, tuple(figures), summary, platforms)


def summary_lines(summary: Summary) -> Sequence[str]:
    """The failure-rate table of each town as plain text, for the end of a run."""
    lines = []
    for town in summary.towns:
        lines.append(f"{summary.town_names[town]}:")
        lines += markdown(failure_table(summary, town)).splitlines()
    return lines
