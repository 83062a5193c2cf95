"""Bird's-eye map of a town and its route (matplotlib, no rendering backend needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import FancyBboxPatch, Rectangle

from vlocbench.sim.town import Town

COLORS = {
    "ground": "#c9d8b6",
    "road": "#5b5e63",
    "sidewalk": "#c8c2b8",
    "building": "#8a7968",
    "tower": "#5d6f86",
    "grass": "#8fbf6a",
    "sand": "#e8d9a8",
    "water": "#6fa8dc",
    "tree": "#2f7d32",
    "route": "#d62728",
}


def draw_town(ax: Axes, town: Town, route: bool = True) -> None:
    """Draw ``town`` into ``ax`` in world metres (x east, y north)."""
    x0, y0, x1, y1 = town.extent
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color=COLORS["road"], zorder=0))
    for rect in town.water:
        _rect(ax, rect, COLORS["water"], 1)
    for rect in town.sand:
        _rect(ax, rect, COLORS["sand"], 1)
    for p in town.platforms:
        rx0, ry0, rx1, ry1 = p.rect
        r = p.corner_radius_m
        ax.add_patch(
            FancyBboxPatch(
                (rx0 + r, ry0 + r),
                rx1 - rx0 - 2 * r,
                ry1 - ry0 - 2 * r,
                boxstyle=f"round,pad={r}" if r > 0 else "square,pad=0",
                color=COLORS["sidewalk"],
                zorder=2,
            )
        )
    for rect in town.grass:
        _rect(ax, rect, COLORS["grass"], 3)
    for b in town.buildings:
        _rect(ax, b.rect, COLORS["tower" if b.tower else "building"], 4)
    if len(town.trees):
        ax.scatter(town.trees[:, 0], town.trees[:, 1], s=4, c=COLORS["tree"], zorder=5, lw=0)
    if len(town.parked_cars):
        ax.scatter(town.parked_cars[:, 0], town.parked_cars[:, 1], s=6, marker="s", c="k", zorder=5)
    if route:
        wp = town.route.waypoints_xy
        ax.plot(wp[:, 0], wp[:, 1], color=COLORS["route"], lw=2.0, zorder=6)
        ax.scatter(wp[0][0], wp[0][1], s=60, c="#2ca02c", zorder=7, label="start", edgecolors="k")
        ax.scatter(
            wp[-1][0], wp[-1][1], s=60, c=COLORS["route"], marker="X", zorder=7, label="goal"
        )
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def _rect(ax: Axes, rect: tuple[float, float, float, float], color: str, z: int) -> None:
    x0, y0, x1, y1 = rect
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color=color, zorder=z, lw=0))


def town_map_figure(town: Town, route: bool = True, width_in: float = 9.0) -> Figure:
    x0, y0, x1, y1 = town.extent
    fig, ax = plt.subplots(figsize=(width_in, width_in * (y1 - y0) / (x1 - x0) + 0.6))
    draw_town(ax, town, route)
    title = f"{town.name}"
    if route:
        title += f": route {town.route.length_m:.0f} m, {town.route.num_turns} turns"
        ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    return fig


def save_town_map(town: Town, path: str | Path, route: bool = True, dpi: int = 110) -> Path:
    """Write a PNG bird's-eye map of ``town`` (with its route) to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = town_map_figure(town, route)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


__all__ = ["draw_town", "save_town_map", "town_map_figure"]
