"""A rendered tour of towns under every condition family: the demo's report for the simulator.

Writes bird's-eye maps, a contact sheet per town (rows: places along the route; columns: conditions)
and ``index.html`` that shows them with the settings used.
"""

from __future__ import annotations

import html
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from vlocbench.config import to_dict
from vlocbench.sim.birdseye import save_town_map
from vlocbench.sim.camera import Camera, Extrinsics, Intrinsics, gallery_camera
from vlocbench.sim.conditions import Conditions, Headlights, Illumination, Viewpoint, Weather
from vlocbench.sim.simulator import Simulator
from vlocbench.sim.town import generate_town, load_town_spec

TOUR_CONDITIONS: dict[str, Conditions] = {
    "day (k=0)": Conditions(),
    "dusk (k=4)": Conditions(illumination=Illumination(k=4)),
    "night (k=8)": Conditions(illumination=Illumination(k=8)),
    "night + headlights": Conditions(
        illumination=Illumination(k=10), headlights=Headlights(on=True)
    ),
    "fog 30 m + rain": Conditions(weather=Weather(fog_visual_range_m=30, rain=0.7, overcast=0.8)),
    "overcast": Conditions(weather=Weather(overcast=1.0)),
    "autumn": Conditions(season="autumn"),
    "winter": Conditions(season="winter"),
    "viewpoint z+4 m, 22.5 deg down": Conditions(viewpoint=Viewpoint(4.0, 22.5)),
}


def tour_sections(
    out: Path,
    towns: Sequence[str] = ("town01", "town10"),
    stops: int = 3,
    thumb_width: int = 320,
    camera: Camera | None = None,
) -> list[str]:
    """Render the tour's images into ``out``; returns an HTML section per town."""
    out.mkdir(parents=True, exist_ok=True)
    camera = camera or gallery_camera()
    forward = Camera(
        "front",
        Intrinsics(camera.intrinsics.width, camera.intrinsics.height, 90.0),
        Extrinsics(x_m=2.0, z_m=1.6, yaw_deg=0.0),
    )
    sections = []
    for name in towns:
        t0 = time.perf_counter()
        town = generate_town(load_town_spec(name))
        with Simulator(town) as sim:
            build_s = time.perf_counter() - t0
            save_town_map(town, out / f"{name}_map.png")
            n = len(town.route.waypoints_xy)
            indices = np.linspace(n * 0.05, n * 0.9, stops).astype(int)
            rows = []
            for idx in indices:
                x, y = town.route.waypoints_xy[idx]
                sim.teleport(float(x), float(y), float(town.route.yaw_rad[idx]))
                tiles = []
                for label, cond in TOUR_CONDITIONS.items():
                    sim.set_conditions(cond)
                    cam = forward if "headlights" in label else camera
                    image = sim.render([cam], frame_id=int(idx))[0].image
                    h = round(image.shape[0] * thumb_width / image.shape[1])
                    tiles.append(cv2.resize(image, (thumb_width, h), interpolation=cv2.INTER_AREA))
                rows.append(np.concatenate(tiles, axis=1))
            sheet = np.concatenate(rows, axis=0)
            cv2.imwrite(
                str(out / f"{name}_conditions.jpg"),
                sheet[:, :, ::-1],
                [cv2.IMWRITE_JPEG_QUALITY, 88],
            )
        sections.append(
            f"<h2>{html.escape(name)}</h2><p>route {town.route.length_m:.0f} m, "
            f"{town.route.num_turns} turns, {len(town.buildings)} buildings; scene built in "
            f"{build_s:.1f} s</p><img src='{name}_map.png' style='max-width:900px'><br>"
            f"<p>Columns: {' | '.join(html.escape(k) for k in TOUR_CONDITIONS)}. The headlights "
            f"column uses a forward camera (the gallery camera looks right).</p>"
            f"<img src='{name}_conditions.jpg' style='max-width:100%'>"
        )
    settings = html.escape(str({k: to_dict(v) for k, v in TOUR_CONDITIONS.items()}))
    sections.append(f"<h3>Conditions</h3><pre style='white-space:pre-wrap'>{settings}</pre>")
    return sections


def write_page(out: Path, title: str, sections: Sequence[str]) -> Path:
    """``out/index.html`` holding ``sections`` under ``title``; returns its path."""
    out.mkdir(parents=True, exist_ok=True)
    page = (
        f"<!doctype html><meta charset='utf-8'><title>{html.escape(title)}</title>"
        f"<body style='font-family:sans-serif;margin:2em'><h1>{html.escape(title)}</h1>"
        + "".join(sections)
        + "</body>"
    )
    index = out / "index.html"
    index.write_text(page)
    return index


def run_tour(
    out_dir: str | Path, towns: Sequence[str] = ("town01", "town10"), stops: int = 3
) -> Path:
    """Render the tour; returns the path of ``index.html``."""
    out = Path(out_dir)
    return write_page(out, "vlocbench: town tour", tour_sections(out, towns, stops))
