"""A map's points against the scene's surfaces, on a real map of the small town."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

from vlocbench.bench.map_check import PLACES, check_points
from vlocbench.errors import LocalizationError
from vlocbench.loc.gallery import Gallery
from vlocbench.loc.mapping import map_info


def test_points_are_placed_on_behind_or_in_front_of_the_surfaces_their_cameras_saw(
    gallery, sift_map, small_sim
):
    map_dir, _ = sift_map
    assert map_info(map_dir)[1] == gallery.root
    rec = pycolmap.Reconstruction(map_dir / "sfm")
    check = check_points(rec, gallery, small_sim.renderer)
    assert set(check.offset_m) == set(rec.points3D)
    shares = check.shares()
    assert set(shares) == set(PLACES) and np.isclose(sum(shares.values()), 1.0)
    # the small town's map: most points lie on what the cameras saw
    assert shares["on"] > 0.9, shares  # 0.94; 0.55 with the grout lines of scene 5

    # a point pushed away from the first camera that sees it, or pulled towards it, along the
    # ray: it still projects where it did in that camera, but no longer lies on the surface
    on = [pid for pid, place in check.places().items() if place == "on"]
    moved = {}
    for pid, scale in zip(on[:2], (1.5, 0.5)):
        point = rec.points3D[pid]
        centre = rec.images[point.track.elements[0].image_id].projection_center()
        point.xyz = centre + scale * (point.xyz - centre)
        moved[pid] = "behind" if scale > 1 else "in front"
    places = check_points(rec, gallery, small_sim.renderer).places()
    assert {pid: places[pid] for pid in moved} == moved


def test_a_map_checked_against_another_gallery_is_a_clear_error(gallery, sift_map, small_sim):
    rec = pycolmap.Reconstruction(sift_map[0] / "sfm")
    other = Gallery(gallery.root, gallery.cameras, gallery.images[:-1])
    with pytest.raises(LocalizationError, match="not in the gallery"):
        check_points(rec, other, small_sim.renderer)
