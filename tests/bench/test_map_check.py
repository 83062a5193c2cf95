"""A map's points against the scene's surfaces, on a real map of the small town."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

from vlocbench.bench.map_check import PLACES, SURFACES, check_points, surface_kind
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

    # what each point's first observation sees: for a point on the surface, the point itself
    on = [pid for pid, place in check.places().items() if place == "on"]
    seen_off_m = [np.linalg.norm(check.seen_xyz_m[pid] - rec.points3D[pid].xyz) for pid in on]
    assert np.median(seen_off_m) < 0.05, np.median(seen_off_m)
    # and its observations see one place
    assert np.median([check.spread_m[pid] for pid in on]) < 0.1

    # a false match: one observation of a point moved 40 px along its image row, as a window
    # matched with its repeat would be, sees another place
    pid = next(p for p in on if rec.points3D[p].track.length() == 2 and check.spread_m[p] < 0.1)
    element = rec.points3D[pid].track.elements[1]
    rec.images[element.image_id].points2D[element.point2D_idx].xy += np.array([40.0, 0.0])
    assert check_points(rec, gallery, small_sim.renderer).spread_m[pid] > 0.5
    rec.images[element.image_id].points2D[element.point2D_idx].xy -= np.array([40.0, 0.0])

    # a point pushed away from the first camera that sees it, or pulled towards it, along the
    # ray: it still projects where it did in that camera, but no longer lies on the surface
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


def test_a_seen_point_is_told_by_the_surface_it_lies_on():
    from vlocbench.sim.town import generate_town, load_town_spec

    town = generate_town(load_town_spec("town01"))
    grass, platform = town.grass[0], town.platforms[0].rect
    centre = np.array([(grass[0] + grass[2]) / 2, (grass[1] + grass[3]) / 2, 0.16])
    assert surface_kind(town, centre) == "grass"
    assert surface_kind(town, centre + np.array([0, 0, 3.0])) == "walls and above"
    x0, y0, x1, y1 = platform
    assert surface_kind(town, np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.15])) == "paving"
    x0, y0, _, _ = town.extent
    assert surface_kind(town, np.array([x0 - 50.0, y0 - 50.0, 0.0])) == "road and open ground"
    tx, ty, trunk_m, crown_m = town.trees[0]
    assert surface_kind(town, np.array([tx, ty, trunk_m + crown_m])) == "trees"
    assert surface_kind(town, np.array([tx + 2.0 * crown_m, ty, trunk_m + crown_m])) != "trees"
    assert set(SURFACES) == {"trees", "walls and above", "grass", "paving", "road and open ground"}
