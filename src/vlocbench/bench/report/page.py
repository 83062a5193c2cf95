"""The report's HTML page: one self-contained file with every table, figure (embedded), example
query images beside the gallery view from the same pose, links to rerun recordings and the episodes
that ended in an error."""

from __future__ import annotations

import base64
import html
import logging
import string
from collections.abc import Callable, Sequence
from importlib import resources
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np

from vlocbench.bench.experiment import setup_label_of
from vlocbench.bench.report.tables import Table, method_label, not_stored_line
from vlocbench.bench.store import EpisodeRow
from vlocbench.bench.summary import BASELINE, Summary
from vlocbench.bench.view import VIEW_DIR

logger = logging.getLogger(__name__)


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


def _setup_of(summary: Summary) -> Callable[[EpisodeRow], str]:
    """A stored episode's setup as the reported plan names it (another plan may have stored it)."""
    labels = summary.plan.setups_by_key
    return lambda r: setup_label_of(labels, r.key, r.setup)


def _errors_html(summary: Summary) -> str:
    if not summary.errors:
        return ""
    setup_of = _setup_of(summary)
    parts = ["<h2 class='err'>Episodes that ended in an error</h2>"]
    for r in summary.errors:
        what = f"{r.town} {r.method} {r.kind} {setup_of(r)} rep {r.repetition}"
        parts.append(f"<p>{html.escape(what)}</p><pre>{html.escape(r.error or '')}</pre>")
    return "\n".join(parts)


def _platforms_html(line: str) -> str:
    """The platforms line, in the warning's colour where they are several."""
    if not line:
        return ""
    return f"<p{' class=err' if line.startswith('WARNING') else ''}>{html.escape(line)}</p>"


def _recordings_html(summary: Summary, rows: Sequence[EpisodeRow], out: Path) -> str:
    """Links to the rerun recordings ``vlocbench view`` wrote next to the report."""
    folder = out.parent / VIEW_DIR
    by_key = {r.key: r for r in rows}
    setup_of = _setup_of(summary)
    items = []
    for path in sorted(folder.glob("*.rrd")) if folder.is_dir() else ():
        r = by_key.get(path.stem)
        what = (
            f"{r.kind} drive, {r.town}, {method_label(r.method)}, {setup_of(r)}, "
            f"repetition {r.repetition}"
            if r
            else "an episode of another run"
        )
        items.append(
            f'<li><a href="../{VIEW_DIR}/{path.name}">{path.name}</a>: {html.escape(what)}</li>'
        )
    hint = (
        "<p>Make one with <code>vlocbench view OUTPUT --setup LABEL --method NAME</code> and open"
        " it with <code>rerun FILE.rrd</code>.</p>"
    )
    return f"<h2>Recordings (rerun)</h2><ul>{''.join(items)}</ul>{hint}" if items else ""


def write_page(
    summary: Summary,
    rows: Sequence[EpisodeRow],
    tables: list[tuple[str, Table]],
    figures: list[Path],
    examples: bool,
    out: Path,
    platforms: str = "",
) -> Path:
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
            not_stored=html.escape(f" ({line})" if (line := not_stored_line(summary)) else ""),
            methods=html.escape(", ".join(m for m in summary.methods if m != BASELINE) or "none"),
            setups=len(summary.setups),
            repetitions=spec.repetitions,
            tables="\n".join(
                f"<h3>{html.escape(caption)}</h3>{_html_table(table)}" for caption, table in tables
            ),
            figures="\n".join(_figure_html(p.read_bytes(), "image/png", p.stem) for p in figures),
            examples=_examples_html(summary) if examples else "",
            recordings=_recordings_html(summary, rows, out),
            error_details=_errors_html(summary),
            platforms=_platforms_html(platforms),
        )
    )
    return page
