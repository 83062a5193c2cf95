"""A map's 3D points against the scene's true surfaces, which simulation knows exactly.

Each point is compared, at every keypoint of the map that observes it, with the depth the renderer
draws there: a point on a surface lies at that depth; a point behind it (farther than what the
camera saw) or in front of it was triangulated from matches of different places that look alike.
``benchmarks/bench_map_points.py`` prints the shares and what the off-surface points cost a
localizer.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np
import pycolmap

from vlocbench.errors import LocalizationError
from vlocbench.geometry import invert_pose
from vlocbench.loc.gallery import Gallery
from vlocbench.sim.renderer import Renderer

PLACES = ("on", "behind", "in front")


@dataclass(frozen=True)
class PointCheck:
    """Per 3D point id, medians over its observations: the point's depth minus the rendered
    depth at the observing keypoint (``offset_m``), and that rendered depth (``surface_m``), in
    metres along each observing camera's optical axis."""

    offset_m: dict[int, float]
    surface_m: dict[int, float]

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
        for p2 in image.points2D:
            if not p2.has_point3D():
                continue
            u, v = np.round(p2.xy - 0.5).astype(int)  # COLMAP's pixel centres are at +0.5
            if 0 <= u < cam.width and 0 <= v < cam.height:
                xyz = reconstruction.points3D[p2.point3D_id].xyz
                z = float(cam_from_world[2, :3] @ xyz + cam_from_world[2, 3])
                seen[p2.point3D_id].append((z - float(depth[v, u]), float(depth[v, u])))
    medians = {pid: np.median(np.array(obs), axis=0) for pid, obs in seen.items()}
    return PointCheck(
        {pid: float(m[0]) for pid, m in medians.items()},
        {pid: float(m[1]) for pid, m in medians.items()},
    )
