"""The report's tables, each a (header, rows) of strings for Markdown, LaTeX and HTML alike: failure
rates with their intervals and the computation time (the paper's Table 2; its viewpoint and weather
tables have the same shape), recall of the ground-truth drive (its Table 5), place recognition,
failures by cause and place, and the odometry's drift."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import matplotlib

matplotlib.use("Agg")
import numpy as np

from vlocbench.bench.across import AcrossTowns, RankAgreement
from vlocbench.bench.consistency import ConfidenceCurve
from vlocbench.bench.metrics import METRICS, PLACE_RADII_M, FailureRate
from vlocbench.bench.requirements import MeasuredAccuracy, OracleSweep
from vlocbench.bench.summary import BASELINE, Cell, Summary

Table = tuple[list[str], list[list[str]]]  # header, rows


def setup_header(summary: Summary, label: str) -> str:
    """A setup's column header: its levels without the dotted prefixes."""
    setup = next(s for s in summary.setups if s.label == label)
    return "; ".join(level_header(key, value) for key, value in setup.levels) or "default"


def level_header(key: str, value: Any) -> str:
    """One swept key's level as a header shows it: ``k=8``, a grouped level's fields."""
    if isinstance(value, dict):
        return ", ".join(f"{k}={value[k]}" for k in sorted(value))
    if key == "cameras":
        return f"{len(value)} cameras"
    return f"{key.split('.')[-1]}={value}"


def method_label(method: str) -> str:
    return "odometry only" if method == BASELINE else method


def not_stored_line(summary: Summary) -> str:
    """What of the plan the report leaves out for want of a stored episode ('' when nothing)."""
    names = [*summary.towns_not_stored, *map(method_label, summary.methods_not_stored)]
    return f"nothing stored yet for {', '.join(names)}: not in this report" if names else ""


def platforms_line(
    summary: Summary,
    records: Mapping[str, Mapping[str, Any]],
    maps: Sequence[Mapping[str, Any]] = (),
) -> str:
    """Which platforms the episodes ran on (:mod:`vlocbench.bench.platform`), by id and what
    drew and computed them, then those that made their maps and galleries (``maps``: each map's
    platform file); a warning where the episodes' are several ('' when none is recorded)."""
    known = sorted(((n, p) for p, n in summary.platforms.items() if p), reverse=True)
    older = summary.platforms.get(None, 0)
    if not known:
        return ""
    records = {**records}
    for m in maps:  # a map's or gallery's platform need not be an episode's
        for made in (m.get("made_on"), m.get("gallery_made_on")):
            if made:
                records.setdefault(made["id"], made)
    described = [f"{n} on {_platform_label(p, records.get(p, {}))}" for n, p in known]
    if older:
        described.append(f"{older} stored before platforms were recorded")
    galleries = {m.get("gallery"): m.get("gallery_made_on") for m in maps}  # several maps each
    made = {
        "maps": _made_on([(m.get("made_on") or {}).get("id") for m in maps], records, known[0][1]),
        "galleries": _made_on(
            [(g or {}).get("id") for g in galleries.values()], records, known[0][1]
        ),
    }
    if made["maps"] == made["galleries"] == "on the same platform":
        described.append("their maps and galleries made on the same platform")
    else:
        described += [f"their {what} made {how}" for what, how in made.items() if how]
    if len(known) == 1:
        return "episodes computed on one platform: " + "; ".join(described)
    return (
        f"WARNING: episodes computed on {len(known)} platforms, which render or compute the same "
        "scene differently, so that one config and seed need not give the same numbers on "
        "each: " + "; ".join(described)
    )


def _made_on(ids: Sequence[str | None], records: Mapping[str, Any], episodes_id: str) -> str:
    """On which platforms the maps (or galleries) with platform ``ids`` were made: 'on the same
    platform' where all on the episodes' (first) one; '' where there are none."""
    counts = Counter(ids)
    if not counts:
        return ""
    if set(counts) == {episodes_id}:
        return "on the same platform"
    return ", ".join(
        f"{n} on {_platform_label(i, records.get(i, {}))}" if i else f"{n} before it was recorded"
        for i, n in sorted(counts.items(), key=lambda x: (x[0] is None, -x[1]))
    )


def _platform_label(platform_id: str, record: Mapping[str, Any]) -> str:
    """``id (GL driver, Mesa version; CPU; torch version on its device)``."""
    d, packages = record.get("details", {}), record.get("packages", {})
    gl = d.get("gl_renderer", "?")
    mesa = d.get("gl_version", "").partition("Mesa ")[2]
    torch = packages.get("torch", "")
    parts = [f"{gl}, Mesa {mesa}" if mesa else gl, d.get("cpu", "?")]
    if torch:
        parts.append(f"torch {torch} on {d.get('torch_device', '?')}")
    return f"{platform_id} ({'; '.join(parts)})"


def fmt(value: float, digits: int = 1) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def planned_repetitions(summary: Summary, method: str) -> int:
    """The failure drives the experiment plans per cell of ``method`` (the odometry line's
    max(repetitions, baseline_repetitions))."""
    s = summary.spec
    return max(s.repetitions, s.baseline_repetitions) if method == BASELINE else s.repetitions


def failure_table(summary: Summary, town: str) -> Table:
    """F, mean [bootstrap 95 %] of each cell; a cell with fewer repetitions stored than planned
    (a run not finished, or a cut of it) says how many it has."""
    header = ["method", *(setup_header(summary, s.label) for s in summary.setups), "CT (ms)"]
    rows = []
    for method in summary.methods:
        row = [method_label(method)]
        cts = []
        planned = planned_repetitions(summary, method)
        for s in summary.setups:
            c = summary.cell(town, method, s.label)
            if c is None or c.failure is None:
                row.append("–")
                continue
            f = c.failure
            text = f"{fmt(f.mean)} [{fmt(f.low)}, {fmt(f.high)}]"
            if f.repetitions < planned:
                text += f" ({f.repetitions} of {planned})"
            row.append(text)
            cts.append(c.ct_s)
        finite = [v for v in cts if np.isfinite(v)]
        row.append(fmt(1000 * float(np.mean(finite)), 0) if finite else "–")
        rows.append(row)
    return header, rows


RecallKind = Literal["6dof", "planar", "fused"]


def recall_table(summary: Summary, town: str, kind: RecallKind = "6dof") -> Table:
    """T1 / T2 / T3 (%) of the ground-truth drive: the raw answers on 6-DoF errors (the paper's,
    with the share of confident wrong answers beside it), on planar errors, or the fused pose."""
    header = ["method", *(setup_header(summary, s.label) for s in summary.setups)]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        row = [method]
        for s in summary.setups:
            c = summary.cell(town, method, s.label)
            r = None
            if c is not None:
                r = {"6dof": c.recall, "planar": c.recall_planar, "fused": c.recall_ekf}[kind]
            text = " / ".join(fmt(100 * v) for v in r[:3]) if r else "–"
            if r and kind == "fused" and c is not None and np.isfinite(c.lock_losses_per_km):
                text += f" ({fmt(c.lock_losses_per_km)}/km)"
            if r and kind == "6dof" and c is not None:
                text += f" ({fmt(100 * c.confident_wrong)} wrong)"
            row.append(text)
        rows.append(row)
    return header, rows


def place_recall_table(summary: Summary, town: str) -> Table:
    """Retrieval alone in the ground-truth drive: Recall@1 / @5 / @10 (%) of a retrieved image
    within each distance, a row per (method, distance)."""
    header = ["method", "within", *(setup_header(summary, s.label) for s in summary.setups)]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        for j, radius_m in enumerate(PLACE_RADII_M):
            row = [method, f"{radius_m:g} m"]
            for s in summary.setups:
                c = summary.cell(town, method, s.label)
                r = c.place_recall if c is not None else None
                values = r[j :: len(PLACE_RADII_M)] if r else ()
                finite = r is not None and any(np.isfinite(v) for v in values)
                row.append(" / ".join(fmt(100 * v) for v in values) if finite else "–")
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
        label = "all" if method == BASELINE else setup_header(summary, s.label)
        rows.append(
            [
                method_label(method),
                label,
                *(fmt(c.failure_by_cause.get(k, 0.0)) for k in causes),
                str(c.timeouts),
            ]
        )
    return header, rows


def baseline_cell(summary: Summary, town: str) -> Cell | None:
    """The odometry-only cell of a town (the first setup's: setups share it unless traffic
    differs)."""
    cells = (summary.cell(town, BASELINE, s.label) for s in summary.setups)
    return next((c for c in cells if c is not None), None)


def drift_table(summary: Summary, town: str) -> Table:
    """The odometry-only EKF's drift as the paper measured it (at the end of each failure-free
    stretch, over its length; the paper: 8.5 % and 0.4 deg/m)."""
    header = ["method", "position drift (%)", "yaw drift (deg/m)", "stretches", "paper"]
    c = baseline_cell(summary, town)
    if c is None:
        return header, []
    d = c.drift
    return header, [
        [
            "odometry only",
            fmt(d.position_percent),
            fmt(d.yaw_deg_per_m, 2),
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
            label = "all" if shared else setup_header(summary, s.label)
            rows.append(
                [
                    method_label(method),
                    label,
                    str(f.failures),
                    str(f.places),
                    worst,
                    fmt(c.tracking_error_m, 2),
                ]
            )
    return header, rows


def declared_metrics_table(summary: Summary, town: str) -> Table:
    """One column per declared metric (:data:`vlocbench.bench.metrics.METRICS`), a row per method
    and setup, each cell combined over the drives and repetitions the metric declares."""
    header = ["method", "setup", *(m.header for m in METRICS.values())]
    rows, seen = [], set()
    for method in summary.methods:
        for s in summary.setups:
            c = summary.cell(town, method, s.label)
            if c is None or c.keys in seen:
                continue
            seen.add(c.keys)  # a shared baseline once
            values = [fmt(c.extra.get(name, float("nan")), m.digits) for name, m in METRICS.items()]
            label = "all" if method == BASELINE else setup_header(summary, s.label)
            rows.append([method_label(method), label, *values])
    return header, rows


def per_town_table(summary: Summary) -> Table:
    """F (failures/km, mean over repetitions) and T1 recall (%) of each method in each town, a
    row per town and a column per (method, setup): the towns side by side."""
    pairs = [(m, s) for s in summary.setups for m in summary.methods]
    header = ["town", *(f"{method_label(m)}, {setup_header(summary, s.label)}" for m, s in pairs)]
    rows = []
    for town in summary.towns:
        row = [summary.town_names[town]]
        for m, s in pairs:
            c = summary.cell(town, m, s.label)
            text = fmt(c.failure.mean) if c is not None and c.failure is not None else "–"
            if c is not None and c.recall:
                text += f" ({fmt(100 * c.recall[0])} %)"
            row.append(text)
        rows.append(row)
    return header, rows


def across_towns_table(summary: Summary, rows: Sequence[AcrossTowns]) -> Table:
    """Each method and setup over the towns: mean F with its intervals over towns and over
    repetitions, and mean T1 recall with its interval over towns."""
    header = ["method", "setup", "F", "over towns", "over repetitions", "T1 (%)", "over towns"]
    out = []
    for r in rows:
        (tl, th), (rl, rh), (ql, qh) = r.failure_towns, r.failure_repetitions, r.recall_towns
        out.append(
            [
                method_label(r.method),
                setup_header(summary, r.setup),
                fmt(r.failure_mean),
                f"[{fmt(tl)}, {fmt(th)}]",
                f"[{fmt(rl)}, {fmt(rh)}]",
                fmt(100 * r.recall_t1),
                f"[{fmt(100 * ql)}, {fmt(100 * qh)}]" if np.isfinite(r.recall_t1) else "–",
            ]
        )
    return header, out


def ranking_table(summary: Summary, agreements: Sequence[RankAgreement]) -> Table:
    """Per setup: the methods ranked by their mean F across towns, Kendall's tau-b of each town's
    ranking against it (lowest and mean) and whether every town ranks them alike."""
    header = ["setup", "ranking across towns (fewest failures first)", "tau-b min / mean", "alike"]
    rows = []
    for a in agreements:
        taus = [t for t in a.tau_by_town.values() if np.isfinite(t)]
        rows.append(
            [
                setup_header(summary, a.setup),
                a.ranking(method_label),
                f"{fmt(a.tau_min, 2)} / {fmt(float(np.mean(taus)) if taus else np.nan, 2)}",
                "yes"
                if a.same_everywhere
                else "no: " + ", ".join(t for t, v in a.tau_by_town.items() if v != 1.0),
            ]
        )
    return header, rows


Curves = Mapping[tuple[str, str, str], ConfidenceCurve]  # (town, method, setup label)


def confidence_table(summary: Summary, town: str, curves: Curves) -> Table:
    """Per method and setup, its answers ranked by confidence (ground-truth drive): the area
    under precision against the share answered, and the confidence threshold that keeps precision
    at 95 % with the share it still answers."""
    header = [
        "method",
        "setup",
        "ranked by",
        "AUC",
        "precision, all answers",
        "95 % precision from",
    ]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        for s in summary.setups:
            curve = curves.get((town, method, s.label))
            if curve is None or curve.queries == 0:
                continue
            overall = curve.precision[-1] if len(curve.precision) else np.nan
            keep = (
                f"{curve.threshold:g} {curve.by} ({fmt(100 * curve.share_at_threshold)} % answered)"
                if np.isfinite(curve.threshold)
                else "never"
            )
            rows.append(
                [
                    method,
                    setup_header(summary, s.label),
                    curve.by,
                    fmt(curve.auc, 2),
                    fmt(100 * overall),
                    keep if curve.by == "inliers" else keep.replace(curve.by, "1/m²"),
                ]
            )
    return header, rows


def verdict_table(summary: Summary, town: str) -> Table:
    """A line per method over the one swept factor (its levels from easy to hard, as the
    experiment lists them; those without its failure episodes stored are skipped): the hardest
    level up to which F stays at most 1 /km, and the first where it is above the odometry line.
    A method the sweep leaves alone (the same episodes at every level, as a real method beside a
    swept oracle) has no line."""
    header = ["method", "F <= 1 /km up to", "worse than odometry only from"]
    if len(summary.axis) != 1:
        return header, []
    labels = [s.label for s in summary.setups]
    odometry = [summary.failure_mean(town, BASELINE, label) for label in labels]
    rows = []
    for method in (m for m in summary.methods if m != BASELINE):
        means = [summary.failure_mean(town, method, label) for label in labels]
        cells = [summary.cell(town, method, label) for label in labels]
        left_alone = len(labels) > 1 and len({c.keys for c in cells if c}) == 1
        stored = [k for k, m in enumerate(means) if np.isfinite(m)]
        if not stored or left_alone:
            continue
        ok = 0
        while ok < len(stored) and means[stored[ok]] <= 1.0:
            ok += 1
        beside = [k for k in stored if np.isfinite(odometry[k])]  # the odometry line driven
        cross = next((k for k in beside if means[k] > odometry[k]), None)
        rows.append(
            [
                method,
                setup_header(summary, labels[stored[ok - 1]]) if ok else "not even the first level",
                setup_header(summary, labels[cross])
                if cross is not None
                else ("never" if beside else "–"),
            ]
        )
    return header, rows


def requirements_table(
    sweeps: Sequence[OracleSweep], placed: Sequence[tuple[str, MeasuredAccuracy, FailureRate]]
) -> Table:
    """Each real method where the oracle sweep places it: the oracle sigma with its answers'
    median error, its answer rate and far answers, its F and the oracle's F at that sigma."""
    header = ["method", "as accurate as the oracle at (m)", "answered (%)", "beyond 5 m (%)", "F"]
    header += [f"{s.method}'s F there" for s in sweeps]
    rows = []
    for name, acc, f in placed:
        rows.append(
            [
                name,
                fmt(acc.equivalent_sigma_m, 2),
                fmt(100 * acc.answer_rate),
                fmt(100 * acc.far_share),
                f"{fmt(f.mean)} [{fmt(f.low)}, {fmt(f.high)}]",
                *(fmt(s.at(acc.equivalent_sigma_m)) for s in sweeps),
            ]
        )
    return header, rows


def markdown(table: Table) -> str:
    header, rows = table
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def latex_escape(text: str) -> str:
    for a, b in (
        ("\\", r"\textbackslash{}"),
        ("_", r"\_"),
        ("%", r"\%"),
        ("&", r"\&"),
        ("#", r"\#"),
        ("–", "--"),
    ):
        text = text.replace(a, b)
    return text


def latex(table: Table, caption: str) -> str:
    header, rows = table
    body = [" & ".join(latex_escape(c) for c in r) + r" \\" for r in rows]
    return "\n".join(
        [
            r"\begin{table}[t]",
            r"\centering",
            rf"\caption{{{latex_escape(caption)}}}",
            r"\resizebox{\linewidth}{!}{%",
            r"\begin{tabular}{l" + "c" * (len(header) - 1) + "}",
            r"\toprule",
            " & ".join(latex_escape(h) for h in header) + r" \\",
            r"\midrule",
            *body,
            r"\bottomrule",
            r"\end{tabular}}",
            r"\end{table}",
        ]
    )
