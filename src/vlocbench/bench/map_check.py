"""A map's 3D points against the scene's true surfaces, which simulation knows exactly.

Each point is compared, at every keypoint of the map that observes it, with the depth the renderer
draws there: a point on a surface lies at that depth; a point behind it (farther than what the
camera saw) or in front of it was triangulated from matches of different places that look alike.
``benchmarks/bench_map_points.py`` prints the shares and what the off-surface points cost a
localizer.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import pycolmap
from numpy.typing import NDArray

from vlocbench.errors import LocalizationError
from vlocbench.geometry import invert_pose
from vlocbench.loc.gallery import Gallery
from vlocbench.sim.renderer import Renderer
from vlocbench.sim.town import Town

PLACES = ("on", "behind", "in front")


@dataclass(frozen=True)
class PointCheck:
    """Per 3D point id, medians over its observations: the point's depth minus the rendered
    depth at the observing keypoint (``offset_m``), and that rendered depth (``surface_m``), in
    metres along each observing camera's optical axis; ``seen_xyz_m``: the world point (3,) its
    first observation sees, on the rendered surface (what a point off every surface was
    triangulated from); ``spread_m``: the greatest distance between the surface points its
    observations see (near 0 for a point matched right; a false match, e.g. between look-alike
    facades of two streets, sees places metres apart)."""

    offset_m: dict[int, float]
    surface_m: dict[int, float]
    seen_xyz_m: dict[int, NDArray[np.float64]]
    spread_m: dict[int, float]

    def places(self, tolerance_m: float = 0.5, relative: float = 0.05) -> dict[int, str]:
        """Each point's place: "on" its surface when the offset is within ``tolerance_m`` or
        ``relative`` of the depth, else "behind" (farther) or "in front"."""
        out = {}
        for pid, offset in self.offset_m.items():
            limit = max(tolerance_m, relative * self.surface_m[pid])
            out[pid] = "on" if abs(offset) <= limit else "behind" if offset > 0 else "in front"
        return out

    def shares(self, tolerance_m: float = 0.5, relative: float = 0.05) -> dict[str, float]:
        """The share of the points at each place of :data:`PLACES`."""
        places = list(self.places(tolerance_m, relative).values())
        return {p: places.count(p) / max(len(places), 1) for p in PLACES}


def check_points(
    reconstruction: pycolmap.Reconstruction, gallery: Gallery, renderer: Renderer
) -> PointCheck:
    """Compare every 3D point of a map's ``reconstruction`` with the scene the ``renderer`` draws
    at the poses of ``gallery``'s images (the map's gallery): one depth render per image."""
    seen: dict[int, list[tuple[float, float]]] = defaultdict(list)
    seen_xyz: dict[int, list[NDArray[np.float64]]] = defaultdict(list)
    entries = {im.name: im for im in gallery.images}
    missing = sorted(im.name for im in reconstruction.images.values() if im.name not in entries)
    if missing:
        raise LocalizationError(
            f"the map's images {missing[:3]} ({len(missing)} in all) are not in the gallery at "
            f"{gallery.root}: check a map against the gallery it was built from"
        )
    for image in reconstruction.images.values():
        entry = entries[image.name]
        cam = gallery.cameras[entry.camera]
        depth = renderer.render_depth(entry.world_from_cam, cam.width, cam.height, cam.fov_deg)
        cam_from_world = invert_pose(entry.world_from_cam)
        cam_from_px = np.linalg.inv(cam.K)
        for p2 in image.points2D:
            if not p2.has_point3D():
                continue
            u, v = np.round(p2.xy - 0.5).astype(int)  # COLMAP's pixel centres are at +0.5
            if 0 <= u < cam.width and 0 <= v < cam.height:
                pid, surface_m = p2.point3D_id, float(depth[v, u])
                xyz = reconstruction.points3D[pid].xyz
                z = float(cam_from_world[2, :3] @ xyz + cam_from_world[2, 3])
                seen[pid].append((z - surface_m, surface_m))
                ray = cam_from_px @ np.append(p2.xy - 0.5, 1.0)
                seen_xyz[pid].append(
                    entry.world_from_cam[:3, :3] @ ray * surface_m + entry.world_from_cam[:3, 3]
                )
    medians = {pid: np.median(np.array(obs), axis=0) for pid, obs in seen.items()}
    return PointCheck(
        {pid: float(m[0]) for pid, m in medians.items()},
        {pid: float(m[1]) for pid, m in medians.items()},
        {pid: xyz[0] for pid, xyz in seen_xyz.items()},
        {pid: _spread_m(np.array(xyz)) for pid, xyz in seen_xyz.items()},
    )


def _spread_m(xyz_m: NDArray[np.float64]) -> float:
    """The greatest distance between any two of the points (N, 3)."""
    return float(np.max(np.linalg.norm(xyz_m[:, None] - xyz_m[None], axis=-1)))


SURFACES = ("trees", "walls and above", "grass", "paving", "road and open ground")


def surface_kind(town: Town, xyz_m: NDArray[np.float64]) -> str:
    """Which of :data:`SURFACES` the scene's point ``xyz_m`` (3,) lies on: a tree's crown (within
    1.1 times its radii, the ellipsoid its leaves are drawn around) or trunk; anything else 0.5 m
    or more above the ground is a wall (or a car, a sign, a lamp); below, the town's grass areas
    and sidewalk platforms (by their rectangles), else the road or the open ground."""
    x, y, z = (float(v) for v in xyz_m)

    def within(rects: Iterable[tuple[float, float, float, float]]) -> bool:
        return any(x0 <= x <= x1 and y0 <= y <= y1 for x0, y0, x1, y1 in rects)

    if len(town.trees):
        tx, ty, trunk_m, crown_m = town.trees.T
        flat_m = np.hypot(tx - x, ty - y)
        crown = (flat_m / crown_m) ** 2 + ((z - trunk_m - 0.9 * crown_m) / (1.1 * crown_m)) ** 2
        if np.any(crown <= 1.1**2) or np.any((flat_m <= 0.3) & (z <= trunk_m + crown_m)):
            return SURFACES[0]
    if z >= 0.5:
        return SURFACES[1]
    if within(town.grass):
        return SURFACES[2]
    return SURFACES[3] if within(p.rect for p in town.platforms) else SURFACES[4]
