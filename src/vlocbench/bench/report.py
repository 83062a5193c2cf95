"""Reports of a run: the paper's tables (Markdown and LaTeX), figures (PNG) and one self-contained
HTML page, written to ``OUTPUT/report/``.

- Failure rate per method and setup, with its bootstrap 95 % interval, the odometry-only row and
  the computation time (the paper's Table 2; its viewpoint and weather tables have the same shape).
- Recall at (0.25 m, 2 deg) / (0.5 m, 5 deg) / (5 m, 10 deg) of the ground-truth drive, raw and of
  the fused pose (its Table 5).
- Failure rate against the swept level with the odometry line; failure rate against recall (its
  Fig. 5); failure sites on the town map (its Fig. 6); computation time per method.
- Example query images per setup beside the gallery view from the same pose.
"""

from __future__ import annotations

import base64
import html
import logging
import string
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from vlocbench.bench.experiment import ExperimentPlan, plan_from_stored
from vlocbench.bench.metrics import PLACE_RADII_M
from vlocbench.bench.paper import FACTOR_OF_AXIS, PaperTable, paper_results, shape
from vlocbench.bench.store import EpisodeRow, StoreError, read_episodes, read_latest_run
from vlocbench.bench.summary import BASELINE, Cell, Summary, summarize
from vlocbench.bench.view import VIEW_DIR

REPORT_DIR = "report"
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf")
Table = tuple[list[str], list[list[str]]]  # header, rows


@dataclass(frozen=True)
class ReportFiles:
    html: Path
    markdown: Path
    latex: Path
    figures: tuple[Path, ...]
    summary: Summary


logger = logging.getLogger(__name__)


# -- tables ---------------------------------------------------------------------------------------
def _short(summary: Summary, label: str) -> str:
    """A setup's column header: its levels without the dotted prefixes."""
    setup = next(s for s in summary.setups if s.label == label)
    if not setup.levels:
        return "default"
    parts = []
    for key, value in setup.levels:
        name = key.split(".")[-1]
        if isinstance(value, dict):
            parts.append(", ".join(f"{k}={value[k]}" for k in sorted(value)))
        elif key == "cameras":
            parts.append(f"{len(value)} cameras")
        else:
            parts.append(f"{name}={value}")
    return "; ".join(parts)


def _method_label(method: str) -> str:
    return "odometry only" if method == BASELINE else method


def _fmt(value: float, digits: int = 1) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def failure_table(summary: Summary, town: str) -> Table:
    header = ["method", *(_short(summary, s.label) for s in summary.setups), "CT (ms)"]
    rows = []
    for method in summary.methods:
        row = [_method_label(method)]
        cts = []
        for s in summary.setups:
            c = summary.cell(town, method, s.label)
            if c is None or c.failure is None:
                row.append("–")
                continue
            f = c.failure
            row.append(f"{_fmt(f.mean)} [{_fmt(f.low)}, {_fmt(f.high)}]")
            cts.append(c.ct_s)
        finite = [v for v in cts if np.isfinite(v)]
        row.append(_fmt(1000 * float(np.mean(finite)), 0) if finite else "–")
        rows.append(row)
    return header, rows


RecallKind = Literal["6dof", "planar", "fused"]


def recall_table(summary: Summary, town: str, kind: RecallKind = "6dof") -> Table:
    """T1 / T2 / T3 (%) of the ground-truth drive: the raw answers on 6-DoF errors (the paper's,
    with the share of confident wrong answers beside it), on planar errors, or the fused pose."""
    header = ["method", *(_short(summary, s.label) for s in summary.setups)]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        row = [method]
        for s in summary.setups:
            c = summary.cell(town, method, s.label)
            r = None
            if c is not None:
                r = {"6dof": c.recall, "planar": c.recall_planar, "fused": c.recall_ekf}[kind]
            text = " / ".join(_fmt(100 * v) for v in r[:3]) if r else "–"
            if r and kind == "fused" and c is not None and np.isfinite(c.lock_losses_per_km):
                text += f" ({_fmt(c.lock_losses_per_km)}/km)"
            if r and kind == "6dof" and c is not None:
                text += f" ({_fmt(100 * c.confident_wrong)} wrong)"
            row.append(text)
        rows.append(row)
    return header, rows


def place_recall_table(summary: Summary, town: str) -> Table:
    """Retrieval alone in the ground-truth drive: Recall@1 / @5 / @10 (%) of a retrieved image
    within each distance, a row per (method, distance)."""
    header = ["method", "within", *(_short(summary, s.label) for s in summary.setups)]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        for j, radius_m in enumerate(PLACE_RADII_M):
            row = [method, f"{radius_m:g} m"]
            for s in summary.setups:
                c = summary.cell(town, method, s.label)
                r = c.place_recall if c is not None else None
                values = r[j :: len(PLACE_RADII_M)] if r else ()
                finite = r is not None and any(np.isfinite(v) for v in values)
                row.append(" / ".join(_fmt(100 * v) for v in values) if finite else "–")
            rows.append(row)
    return header, rows


def cause_table(summary: Summary, town: str) -> Table:
    """F split by the cause of the failures (they add up to F), and the time-outs."""
    cells = [
        (method, s, c)
        for method in summary.methods
        for s in summary.setups
        if (c := summary.cell(town, method, s.label)) is not None and c.failure is not None
    ]
    causes = sorted({k for _, _, c in cells for k in c.failure_by_cause} | {"collision"})
    header = ["method", "setup", *causes, "timed-out episodes"]
    rows, seen = [], set()
    for method, s, c in cells:
        if c.keys in seen:  # a shared baseline once
            continue
        seen.add(c.keys)
        label = "all" if method == BASELINE else _short(summary, s.label)
        rows.append([_method_label(method), label,
                     *(_fmt(c.failure_by_cause.get(k, 0.0)) for k in causes), str(c.timeouts)])  # fmt: skip
    return header, rows


def _baseline_cell(summary: Summary, town: str) -> Cell | None:
    """The odometry-only cell of a town (the first setup's: setups share it unless traffic
    differs)."""
    cells = (summary.cell(town, BASELINE, s.label) for s in summary.setups)
    return next((c for c in cells if c is not None), None)


def drift_table(summary: Summary, town: str) -> Table:
    """The odometry-only EKF's drift as the paper measured it (at the end of each failure-free
    stretch, over its length; the paper: 8.5 % and 0.4 deg/m)."""
    header = ["method", "position drift (%)", "yaw drift (deg/m)", "stretches", "paper"]
    c = _baseline_cell(summary, town)
    if c is None:
        return header, []
    d = c.drift
    return header, [
        [
            "odometry only",
            _fmt(d.position_percent),
            _fmt(d.yaw_deg_per_m, 2),
            str(d.segments),
            "8.5 % and 0.40 deg/m",
        ]
    ]


def fragmentation_table(summary: Summary, town: str) -> Table:
    """Where the failures happen: over the repetitions of each method and setup, how many, at how
    many distinct 25 m stretches of the route, the worst stretch, and the tracking error."""
    header = ["method", "setup", "failures", "places", "worst stretch (share)", "tracking (m)"]
    rows = []
    for method in summary.methods:
        seen = set()
        for s in summary.setups:
            c = summary.cell(town, method, s.label)
            if c is None or c.fragmentation is None or c.keys in seen:
                continue
            seen.add(c.keys)  # a shared baseline once
            f = c.fragmentation
            worst = f"{f.worst_s_m:.0f} m ({100 * f.top_share:.0f} %)" if f.failures else "–"
            shared = method == BASELINE and all(
                (x := summary.cell(town, method, o.label)) is None or x.keys == c.keys
                for o in summary.setups
            )
            label = "all" if shared else _short(summary, s.label)
            rows.append([_method_label(method), label,
                         str(f.failures), str(f.places), worst, _fmt(c.tracking_error_m, 2)])  # fmt: skip
    return header, rows


# -- beside the paper ------------------------------------------------------------------------------
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


def _ours(summary: Summary, town: str, method: str) -> tuple[list[float], list[float]]:
    """F and T1 recall (%) of a method per setup, NaN where missing."""
    f, t1 = [], []
    for s in summary.setups:
        c = summary.cell(town, method, s.label)
        f.append(c.failure.mean if c is not None and c.failure is not None else float("nan"))
        t1.append(100 * c.recall[0] if c is not None and c.recall else float("nan"))
    return f, t1


def paper_comparison_tables(summary: Summary) -> list[tuple[str, Table]]:
    """Our failure rates and recall beside the paper's, level by level where the levels match,
    and the shape measures of :mod:`vlocbench.bench.paper` for every method of both."""
    axis = _one_axis(summary)
    table = None if axis is None else _paper_table(axis[0])
    if axis is None or table is None:
        return []
    ours_levels = [_paper_level(table.factor, v) for v in axis[1]]
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


def _paper_failure_table(summary: Summary, town: str, table: PaperTable,
                         ours_levels: list[Any]) -> tuple[str, Table]:  # fmt: skip
    name, paper = summary.town_names[town], paper_results()
    shared = [lv for lv in table.levels if lv in ours_levels]
    header = ["source", "method", *(_level_text(lv) for lv in shared)]
    rows = []
    for method in summary.methods:
        f, _ = _ours(summary, town, method)
        rows.append(["vlocbench", _method_label(method),
                     *(_fmt(f[ours_levels.index(lv)]) for lv in shared)])  # fmt: skip
    for method, f in table.failure_rate[name].items():
        rows.append(["paper", method, *(_fmt(f[table.levels.index(lv)]) for lv in shared)])
    rows.append(["paper", "odometry only",
                 *(_fmt(paper.odometry_failure_rate[name]) for _ in shared)])  # fmt: skip
    return (f"{name}: failure rate F (failures/km) beside the paper's ({paper.citation})",
            (header, rows))  # fmt: skip


def _paper_recall_table(summary: Summary, town: str, table: PaperTable,
                        ours_levels: list[Any]) -> tuple[str, Table]:  # fmt: skip
    name = summary.town_names[town]
    shared = [lv for lv in table.recall_levels if lv in ours_levels]
    header = ["source", "method", *(_level_text(lv) for lv in shared)]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        _, t1 = _ours(summary, town, method)
        rows.append(["vlocbench", method, *(_fmt(t1[ours_levels.index(lv)]) for lv in shared)])
    for method, t1 in table.recall_t1[name].items():
        rows.append(["paper", method,
                     *(_fmt(t1[table.recall_levels.index(lv)]) for lv in shared)])  # fmt: skip
    return f"{name}: T1 recall (%, 6-DoF, ground-truth drive) beside the paper's", (header, rows)


def _paper_shape_table(summary: Summary, town: str, table: PaperTable,
                       ours_levels: list[Any]) -> tuple[str, Table]:  # fmt: skip
    name = summary.town_names[town]
    odo_cell = _baseline_cell(summary, town)
    odo = odo_cell.failure.mean if odo_cell and odo_cell.failure else float("nan")
    paper_odo = paper_results().odometry_failure_rate[name]
    header = ["source", "method", "F easiest", "Spearman(F, level)", "F reaches odometry at",
              "F above odometry up to T1 (%)"]  # fmt: skip
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        f, t1 = _ours(summary, town, method)
        rows.append(["vlocbench", method, *_shape_cells(shape(f, odo, None, t1), ours_levels)])
    for method, f in table.failure_rate[name].items():
        t1_by_level = dict(zip(table.recall_levels, table.recall_t1.get(name, {}).get(method, ())))
        t1 = [t1_by_level.get(lv, float("nan")) for lv in table.levels]
        rows.append(["paper", method,
                     *_shape_cells(shape(f, paper_odo, None, t1), list(table.levels))])  # fmt: skip
    return (f"{name}: shape of F over the levels, ours (odometry only {_fmt(odo)}/km) and the "
            f"paper's ({_fmt(paper_odo)}/km)", (header, rows))  # fmt: skip


def _level_text(level: Any) -> str:
    if isinstance(level, tuple):
        return "z=" + ", θ=".join(f"{v:g}" for v in level)
    return f"{level:g}"


def _shape_cells(sh: Any, levels: Sequence[Any]) -> list[str]:
    reach = "never" if sh.odometry_level is None else _level_text(levels[sh.odometry_level])
    return [_fmt(sh.f_easiest), _fmt(sh.rank_correlation, 2), reach,
            _fmt(sh.worse_than_odometry_below_t1)]  # fmt: skip


def _markdown(table: Table) -> str:
    header, rows = table
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _latex_escape(text: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"),
                 ("#", r"\#"), ("–", "--")):  # fmt: skip
        text = text.replace(a, b)
    return text


def _latex(table: Table, caption: str) -> str:
    header, rows = table
    body = [" & ".join(_latex_escape(c) for c in r) + r" \\" for r in rows]
    return "\n".join([
        r"\begin{table}[t]", r"\centering", rf"\caption{{{_latex_escape(caption)}}}",
        r"\resizebox{\linewidth}{!}{%", r"\begin{tabular}{l" + "c" * (len(header) - 1) + "}",
        r"\toprule", " & ".join(_latex_escape(h) for h in header) + r" \\", r"\midrule",
        *body, r"\bottomrule", r"\end{tabular}}", r"\end{table}",
    ])  # fmt: skip


def _tables(summary: Summary) -> list[tuple[str, Table]]:
    out = []
    for town in summary.towns:
        name = summary.town_names[town]
        out.append((f"{name}: failure rate F (failures/km, mean [bootstrap 95 % CI] over "
                    f"{summary.spec.repetitions} repetitions) and computation time per query",
                    failure_table(summary, town)))  # fmt: skip
        out.append((f"{name}: failure rate by cause (failures/km; the paper counts collisions) "
                    "and episodes that ran out of time", cause_table(summary, town)))  # fmt: skip
        if summary.spec.recall and summary.spec.methods:
            out.append((f"{name}: recall (%) at (0.25 m, 2°) / (0.5 m, 5°) / (5 m, 10°) on 6-DoF "
                        "errors, ground-truth drive, raw localization (share of answers confident "
                        "and wrong: beyond (5 m, 10°))", recall_table(summary, town)))  # fmt: skip
            out.append((f"{name}: place recognition alone, Recall@1 / @5 / @10 (%) of a retrieved "
                        "gallery image within 5, 10 and 25 m, same drive",
                        place_recall_table(summary, town)))  # fmt: skip
            out.append((f"{name}: recall (%) on planar (x, y, yaw) errors, same drive",
                        recall_table(summary, town, "planar")))  # fmt: skip
            out.append((f"{name}: recall (%) of the fused (EKF) pose at every step, same drive "
                        "(lock losses per km: the EKF reset at the truth)",
                        recall_table(summary, town, "fused")))  # fmt: skip
        if summary.spec.baseline:
            out.append((f"{name}: wheel-odometry drift of the EKF, at the end of each failure-free "
                        "stretch over its length", drift_table(summary, town)))  # fmt: skip
        out.append((f"{name}: where failures happen (25 m stretches of the route) and the "
                    "mean tracking error", fragmentation_table(summary, town)))  # fmt: skip
    return out + paper_comparison_tables(summary)


# -- figures --------------------------------------------------------------------------------------
def _x_axis(summary: Summary) -> tuple[list[float], list[str], str]:
    values = summary.level_values()
    labels = [_short(summary, s.label) for s in summary.setups]
    if values is not None:
        return values, [f"{v:g}" for v in values], summary.axis[0]
    return list(range(len(labels))), labels, ", ".join(summary.axis) or "setup"


def _save(fig: plt.Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def failure_figure(summary: Summary, town: str, path: Path) -> Path:
    x, ticks, xlabel = _x_axis(summary)
    fig, ax = plt.subplots(figsize=(7, 4))
    for method, color in zip(summary.methods, COLORS * 4):
        cells = [summary.cell(town, method, s.label) for s in summary.setups]
        f = [c.failure if c else None for c in cells]
        mean = np.array([v.mean if v else np.nan for v in f])
        low = np.array([v.low if v else np.nan for v in f])
        high = np.array([v.high if v else np.nan for v in f])
        if method == BASELINE:
            ax.plot(x, mean, "--", color="0.4", label="odometry only")
            continue
        ax.errorbar(x, mean, yerr=[mean - low, high - mean], fmt="o-", color=color, capsize=3,
                    label=method)  # fmt: skip
    ax.set_xticks(
        x, ticks, rotation=30 if len(ticks) > 6 else 0, ha="right" if len(ticks) > 6 else "center"
    )
    ax.set_xlabel(xlabel)
    ax.set_ylabel("failure rate F (1/km)")
    ax.set_ylim(bottom=0)
    ax.set_title(f"{summary.town_names[town]}: failure rate (95 % CI)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def failure_vs_recall_figure(summary: Summary, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(6, 4.5))
    markers = "osD^v<>"
    for method, color in zip(summary.methods, COLORS * 4):
        if method == BASELINE:
            continue
        for town, marker in zip(summary.towns, markers * 4):
            pts = [(100 * c.recall[0], c.failure.mean) for s in summary.setups
                   if (c := summary.cell(town, method, s.label)) and c.recall and c.failure]  # fmt: skip
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


# -- example images -------------------------------------------------------------------------------
def example_images(
    summary: Summary, town: str, width_px: int = 320
) -> list[tuple[str, bytes, bytes]]:
    """(setup label, query JPEG, gallery-view JPEG) per setup, from one pose a third of the way
    along the route: what the localizer sees against what the map was built from."""
    import cv2

    from vlocbench.bench.towns import route_named, town_named
    from vlocbench.sim import Simulator

    spec = summary.spec
    route = route_named(town, spec.route_length_m)
    j = len(route) // 3
    pose = (float(route.xy[j, 0]), float(route.xy[j, 1]), float(route.yaw_rad[j]))

    def jpeg(image: np.ndarray) -> bytes:
        h, w = image.shape[:2]
        small = cv2.resize(image, (width_px, round(h * width_px / w)), interpolation=cv2.INTER_AREA)
        return cv2.imencode(
            ".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85]
        )[1].tobytes()

    with Simulator(town_named(town), spec.gallery.conditions) as sim:
        sim.teleport(*pose)
        gallery_view = jpeg(sim.render([spec.gallery.camera])[0].image)
    out = []
    # one scene per traffic level (its cars are part of it), in the setups' order
    for traffic in dict.fromkeys(s.conditions.traffic for s in summary.setups):
        group = [s for s in summary.setups if s.conditions.traffic == traffic]
        with Simulator(town_named(town), group[0].conditions) as sim:
            for s in group:
                sim.set_conditions(s.conditions)
                sim.teleport(*pose)
                out.append((s.label, jpeg(sim.render(s.cameras[:1])[0].image), gallery_view))
    order = {s.label: k for k, s in enumerate(summary.setups)}
    return sorted(out, key=lambda item: order[item[0]])


# -- the report -----------------------------------------------------------------------------------
def _html_table(table: Table) -> str:
    header, rows = table
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _img(data: bytes, mime: str, alt: str) -> str:
    return (
        f'<img alt="{html.escape(alt)}" src="data:{mime};base64,{base64.b64encode(data).decode()}">'
    )


def _page_template() -> string.Template:
    return string.Template(
        resources.files("vlocbench.bench.data").joinpath("report.html").read_text()
    )


def _figure_html(data: bytes, mime: str, caption: str) -> str:
    return f"<figure>{_img(data, mime, caption)}<figcaption>{html.escape(caption)}</figcaption></figure>"


def _examples_html(summary: Summary) -> str:
    parts = ["<h2>Query images and the gallery view from the same pose</h2>"]
    for town in summary.towns:
        name = summary.town_names[town]
        logger.info(f"report: rendering example images of {name}")
        for label, query, gallery in example_images(summary, town):
            parts.append(
                f"<div><h4>{html.escape(name)}: {html.escape(label)}</h4>"
                + _figure_html(query, "image/jpeg", "query")
                + _figure_html(gallery, "image/jpeg", "gallery")
                + "</div>"
            )
    return "\n".join(parts)


def _errors_html(errors: Sequence[EpisodeRow]) -> str:
    if not errors:
        return ""
    parts = ["<h2 class='err'>Episodes that ended in an error</h2>"]
    for r in errors:
        what = f"{r.town} {r.method} {r.kind} {r.setup} rep {r.repetition}"
        parts.append(f"<p>{html.escape(what)}</p><pre>{html.escape(r.error or '')}</pre>")
    return "\n".join(parts)


def _write_tables(out: Path, tables: list[tuple[str, Table]]) -> tuple[Path, Path]:
    """``tables.md`` and ``tables.tex``."""
    md = out / "tables.md"
    md.write_text("\n\n".join(f"**{caption}**\n\n{_markdown(t)}" for caption, t in tables) + "\n")
    tex = out / "tables.tex"
    tex.write_text(
        "% needs \\usepackage{booktabs, graphicx}\n"
        + "\n\n".join(_latex(t, c) for c, t in tables)
        + "\n"
    )
    return md, tex


def _write_figures(summary: Summary, out: Path) -> list[Path]:
    from vlocbench.bench.towns import town_named

    figures: list[Path] = []
    for town in summary.towns:
        name = summary.town_names[town]
        figures.append(failure_figure(summary, town, out / f"failure_rate_{name}.png"))
        figures.append(
            crash_sites_figure(summary, town, town_named(town), out / f"failure_sites_{name}.png")
        )
    if summary.spec.methods:
        if summary.spec.recall and summary.spec.failure:
            figures.append(failure_vs_recall_figure(summary, out / "failure_vs_recall.png"))
        figures.append(computation_time_figure(summary, out / "computation_time.png"))
    return figures


def _recordings_html(rows: Sequence[EpisodeRow], out: Path) -> str:
    """Links to the rerun recordings ``vlocbench view`` wrote next to the report."""
    folder = out.parent / VIEW_DIR
    by_key = {r.key: r for r in rows}
    items = []
    for path in sorted(folder.glob("*.rrd")) if folder.is_dir() else ():
        r = by_key.get(path.stem)
        what = (f"{r.kind} drive, {r.town}, {_method_label(r.method)}, {r.setup}, "
                f"repetition {r.repetition}" if r else "an episode of another run")  # fmt: skip
        items.append(
            f'<li><a href="../{VIEW_DIR}/{path.name}">{path.name}</a>: {html.escape(what)}</li>'
        )
    hint = ("<p>Make one with <code>vlocbench view OUTPUT --setup LABEL --method NAME</code> and open"
            " it with <code>rerun FILE.rrd</code>.</p>")  # fmt: skip
    return f"<h2>Recordings (rerun)</h2><ul>{''.join(items)}</ul>{hint}" if items else ""


def _write_page(summary: Summary, rows: Sequence[EpisodeRow], tables: list[tuple[str, Table]],
                figures: list[Path], examples: bool, out: Path) -> Path:  # fmt: skip
    spec = summary.spec
    page = out / "index.html"
    page.write_text(
        _page_template().substitute(
            title=html.escape(spec.name),
            episodes=summary.episodes,
            planned=summary.planned,
            errors=len(summary.errors),
            spec_hash=spec.spec_hash,
            towns=html.escape(", ".join(summary.town_names[t] for t in summary.towns)),
            methods=html.escape(", ".join(m.name for m in spec.methods) or "none"),
            setups=len(summary.setups),
            repetitions=spec.repetitions,
            tables="\n".join(
                f"<h3>{html.escape(caption)}</h3>{_html_table(table)}" for caption, table in tables
            ),
            figures="\n".join(_figure_html(p.read_bytes(), "image/png", p.stem) for p in figures),
            examples=_examples_html(summary) if examples else "",
            recordings=_recordings_html(rows, out),
            error_details=_errors_html(summary.errors),
        )
    )
    return page


def write_report(
    output_dir: str | Path, examples: bool = True, plan: ExperimentPlan | None = None
) -> ReportFiles:
    """Write the tables, figures and the HTML page of the latest run in ``output_dir``, or of
    ``plan`` over every episode of it stored there (run in parts, by several runs)."""
    if plan is None:
        stored, rows = read_latest_run(output_dir)
        plan = plan_from_stored(stored)
    else:
        rows = read_episodes(output_dir)
        keys = {t.key for t in plan.tasks()}
        rows = [r for r in rows if r.key in keys]
        if not rows:
            raise StoreError(f"{output_dir} holds no episode of experiment {plan.name!r}")
    summary = summarize(plan, rows)
    out = Path(output_dir) / REPORT_DIR
    out.mkdir(parents=True, exist_ok=True)
    tables = _tables(summary)
    md, tex = _write_tables(out, tables)
    figures = _write_figures(summary, out)
    page = _write_page(summary, rows, tables, figures, examples, out)
    return ReportFiles(page, md, tex, tuple(figures), summary)


def summary_lines(summary: Summary) -> Sequence[str]:
    """The failure-rate table of each town as plain text, for the end of a run."""
    lines = []
    for town in summary.towns:
        lines.append(f"{summary.town_names[town]}:")
        lines += _markdown(failure_table(summary, town)).splitlines()
    return lines
