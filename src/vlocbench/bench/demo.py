"""The README's main job: a tour of the towns under every condition, then closed-loop drives.

Each town's route is driven on ground truth, on an oracle localizer (true pose plus noise) and on
wheel odometry alone (several seeds); the report shows failure rates, tracking errors and the
trajectories with their failure sites on the map.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from vlocbench.bench.episode import EpisodeConfig, plan_town_route, run_episode
from vlocbench.bench.localizer import OracleConfig, OracleLocalizer
from vlocbench.bench.plots import save_episode_map
from vlocbench.bench.records import EpisodeResult
from vlocbench.config import config_hash
from vlocbench.sim import Simulator
from vlocbench.sim.tour import tour_sections, write_page
from vlocbench.sim.town import generate_town, load_town_spec

ORACLE = OracleConfig(position_sigma_m=0.1, yaw_sigma_deg=1.0)


def _row(label: str, runs: list[EpisodeResult]) -> str:
    rates = [r.failures_per_km for r in runs]
    cells = (
        label,
        str(len(runs)),
        f"{np.mean(rates):.1f}",
        str(sum(r.failures for r in runs)),
        f"{np.mean([r.tracking_error_mean_m for r in runs]):.2f}",
        f"{np.mean([r.real_time_factor for r in runs]):.0f}x",
    )
    return "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>"


def drive_sections(out: Path, towns: tuple[str, ...], seeds: int = 3) -> list[str]:
    """Drive each town's route; writes a map per town into ``out``, returns HTML sections."""
    sections = []
    config = EpisodeConfig()
    for name in towns:
        town = generate_town(load_town_spec(name))
        sim = Simulator(town)
        path = plan_town_route(town)
        gt = run_episode(sim, path, None, EpisodeConfig(mode="ground_truth"))
        oracle = run_episode(sim, path, OracleLocalizer(ORACLE), config)
        odometry = [run_episode(sim, path, None, EpisodeConfig(seed=s)) for s in range(seeds)]
        sim.close()
        save_episode_map(
            town, {"oracle": oracle, "odometry only": odometry[0]}, out / f"{name}_drive.png"
        )
        rows = (
            _row("ground truth (driving on the true pose)", [gt])
            + _row(
                f"oracle localizer ({ORACLE.position_sigma_m} m, {ORACLE.yaw_sigma_deg} deg)",
                [oracle],
            )
            + _row("wheel odometry only", odometry)
        )
        sections.append(
            f"<h2>{html.escape(name)}: closed-loop drives</h2><p>route {path.length_m:.0f} m; "
            f"episode config {config_hash(config)}</p>"
            "<table border=1 cellpadding=4 style='border-collapse:collapse'><tr><th>driving on"
            "</th><th>episodes</th><th>failures per km</th><th>failures</th><th>mean tracking "
            "error [m]</th><th>speed vs real time</th></tr>"
            f"{rows}</table><img src='{name}_drive.png' style='max-width:900px'>"
        )
    return sections


def run_demo(
    out_dir: str | Path, towns: tuple[str, ...] = ("town01", "town10"), stops: int = 3
) -> Path:
    out = Path(out_dir)
    sections = drive_sections(out, towns) + tour_sections(out, towns, stops)
    return write_page(out, "vlocbench demo", sections)
