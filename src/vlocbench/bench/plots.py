"""Figures of episodes (matplotlib, Agg): trajectories and failure sites on the bird's-eye map."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from vlocbench.bench.records import EpisodeResult
from vlocbench.sim.birdseye import town_map_figure
from vlocbench.sim.town import Town

EPISODE_COLORS = ("#1f77b4", "#ff7f0e", "#9467bd", "#17becf", "#8c564b")


def save_episode_map(
    town: Town, episodes: Mapping[str, EpisodeResult], path: str | Path, dpi: int = 110
) -> Path:
    """The town with each episode's true trajectory (solid), EKF trajectory (dotted) and
    re-initialization sites (crosses where the car failed); ``episodes`` maps label -> result."""
    fig = town_map_figure(town, route=True)
    ax = fig.axes[0]
    for (label, r), color in zip(episodes.items(), EPISODE_COLORS * 4):
        tr = r.trajectory
        # break the lines where the car was teleported back to the route
        cuts = np.searchsorted(tr.time_s, [x.time_s for x in r.reinitializations])
        tx, ty, ex, ey = (
            np.insert(a, cuts, np.nan) for a in (tr.true_x_m, tr.true_y_m, tr.ekf_x_m, tr.ekf_y_m)
        )
        ax.plot(tx, ty, color=color, lw=1.2, zorder=8, label=f"{label}: true")
        ax.plot(ex, ey, color=color, lw=0.8, ls=":", zorder=8, label="  EKF")
        if r.reinitializations:
            xs = [x.x_m for x in r.reinitializations]
            ys = [x.y_m for x in r.reinitializations]
            ax.scatter(
                xs, ys, marker="x", s=40, c=color, zorder=9, label=f"  {r.failures} failures"
            )
    ax.legend(loc="best", fontsize=7)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
