"""Our failure rates and recall beside the paper's published tables, level by level where the levels
match, and the shape measures of :mod:`vlocbench.bench.paper` for every method of both."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from vlocbench.bench.paper import FACTOR_OF_AXIS, PaperTable, paper_results, shape
from vlocbench.bench.report.tables import Table, baseline_cell, fmt, method_label
from vlocbench.bench.summary import BASELINE, Summary


def _paper_level(factor: str, value: Any) -> Any:
    """A setup's level in the key of the paper's table (k; (z, pitch); fog visual range)."""
    if factor == "viewpoint" and isinstance(value, dict):
        return (float(value.get("dz_m", 0.0)), float(value.get("pitch_down_deg", 0.0)))
    if factor == "weather" and isinstance(value, dict):
        value = value.get("fog_visual_range_m")
    return None if value is None else float(value)


def _one_axis(summary: Summary) -> tuple[str, list[Any]] | None:
    """The run's one swept key and each setup's value of it (a sweep of one level counts)."""
    if summary.axis:
        if len(summary.axis) != 1:
            return None
        return summary.axis[0], [s.levels[0][1] for s in summary.setups]
    if len(summary.spec.sweep) != 1:
        return None
    key, value = summary.spec.sweep[0]
    one = value[0] if isinstance(value, list | tuple) and len(value) == 1 else value
    return key, [one for _ in summary.setups]


def _paper_table(key: str) -> PaperTable | None:
    factor = FACTOR_OF_AXIS.get(key) or FACTOR_OF_AXIS.get(key.split(".")[0])
    return None if factor is None else paper_results().tables[factor]


def ours_per_setup(summary: Summary, town: str, method: str) -> tuple[list[float], list[float]]:
    """F and T1 recall (%) of a method per setup, NaN where missing."""
    f, t1 = [], []
    for s in summary.setups:
        c = summary.cell(town, method, s.label)
        f.append(summary.failure_mean(town, method, s.label))
        t1.append(100 * c.recall[0] if c is not None and c.recall else float("nan"))
    return f, t1


def paper_axis(summary: Summary) -> tuple[PaperTable, list[Any]] | None:
    """The paper's table of the run's one swept factor and each setup's level in that table's
    key; None when the run sweeps no factor of the paper, or more than one."""
    axis = _one_axis(summary)
    table = None if axis is None else _paper_table(axis[0])
    if axis is None or table is None:
        return None
    return table, [_paper_level(table.factor, v) for v in axis[1]]


def paper_comparison_tables(summary: Summary) -> list[tuple[str, Table]]:
    """Our failure rates and recall beside the paper's, level by level where the levels match,
    and the shape measures of :mod:`vlocbench.bench.paper` for every method of both."""
    found = paper_axis(summary)
    if found is None:
        return []
    table, ours_levels = found
    out = []
    for town in summary.towns:
        name = summary.town_names[town]
        if name not in table.failure_rate:
            continue
        out.append(_paper_failure_table(summary, town, table, ours_levels))
        if table.recall_t1:
            out.append(_paper_recall_table(summary, town, table, ours_levels))
        if len(ours_levels) > 1:  # shapes need an axis
            out.append(_paper_shape_table(summary, town, table, ours_levels))
    return out


def _paper_failure_table(
    summary: Summary, town: str, table: PaperTable, ours_levels: list[Any]
) -> tuple[str, Table]:
    name, paper = summary.town_names[town], paper_results()
    shared = [lv for lv in table.levels if lv in ours_levels]
    header = ["source", "method", *(level_text(lv) for lv in shared)]
    rows = []
    for method in summary.methods:
        f, _ = ours_per_setup(summary, town, method)
        rows.append(
            ["vlocbench", method_label(method), *(fmt(f[ours_levels.index(lv)]) for lv in shared)]
        )
    for method, paper_f in table.failure_rate[name].items():
        rows.append(["paper", method, *(fmt(paper_f[table.levels.index(lv)]) for lv in shared)])
    rows.append(
        ["paper", "odometry only", *(fmt(paper.odometry_failure_rate[name]) for _ in shared)]
    )
    return (
        f"{name}: failure rate F (failures/km) beside the paper's ({paper.citation})",
        (header, rows),
    )


def _paper_recall_table(
    summary: Summary, town: str, table: PaperTable, ours_levels: list[Any]
) -> tuple[str, Table]:
    name = summary.town_names[town]
    shared = [lv for lv in table.recall_levels if lv in ours_levels]
    header = ["source", "method", *(level_text(lv) for lv in shared)]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        _, t1 = ours_per_setup(summary, town, method)
        rows.append(["vlocbench", method, *(fmt(t1[ours_levels.index(lv)]) for lv in shared)])
    for method, paper_t1 in table.recall_t1[name].items():
        rows.append(
            ["paper", method, *(fmt(paper_t1[table.recall_levels.index(lv)]) for lv in shared)]
        )
    return f"{name}: T1 recall (%, 6-DoF, ground-truth drive) beside the paper's", (header, rows)


def _paper_shape_table(
    summary: Summary, town: str, table: PaperTable, ours_levels: list[Any]
) -> tuple[str, Table]:
    name = summary.town_names[town]
    odo_cell = baseline_cell(summary, town)
    odo = odo_cell.failure.mean if odo_cell and odo_cell.failure else float("nan")
    paper_odo = paper_results().odometry_failure_rate[name]
    header = [
        "source",
        "method",
        "F easiest",
        "Spearman(F, level)",
        "F reaches odometry at",
        "F above odometry up to T1 (%)",
    ]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        f, t1 = ours_per_setup(summary, town, method)
        rows.append(["vlocbench", method, *_shape_cells(shape(f, odo, None, t1), ours_levels)])
    for method, paper_f in table.failure_rate[name].items():
        t1_by_level = dict(zip(table.recall_levels, table.recall_t1.get(name, {}).get(method, ())))
        paper_t1 = [t1_by_level.get(lv, float("nan")) for lv in table.levels]
        rows.append(
            [
                "paper",
                method,
                *_shape_cells(shape(paper_f, paper_odo, None, paper_t1), list(table.levels)),
            ]
        )
    return (
        f"{name}: shape of F over the levels, ours (odometry only {fmt(odo)}/km) and the "
        f"paper's ({fmt(paper_odo)}/km)",
        (header, rows),
    )


def level_text(level: Any) -> str:
    if isinstance(level, tuple):
        return "z=" + ", θ=".join(f"{v:g}" for v in level)
    return f"{level:g}"


def _shape_cells(sh: Any, levels: Sequence[Any]) -> list[str]:
    reach = "never" if sh.odometry_level is None else level_text(levels[sh.odometry_level])
    return [
        fmt(sh.f_easiest),
        fmt(sh.rank_correlation, 2),
        reach,
        fmt(sh.worse_than_odometry_below_t1),
    ]
