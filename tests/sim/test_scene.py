"""The town's scene: facade relief, where shops go (real renders of the small town)."""

import numpy as np

from vlocbench.sim import generate_town, load_town_spec
from vlocbench.sim.scene import (
    GROUND_FLOOR_M,
    building_side,
    shop_bays,
    shop_plan,
    wall_variants,
)
from vlocbench.sim.textures import WINDOW_RECESS_M


def test_windows_sit_behind_the_walls_face(small_town, small_sim):
    """Seen head-on from 2 m, a masonry wall's depth has two levels: its face and, 0.2 m
    further, its windows."""
    fh = small_town.spec.buildings.floor_height_m
    depths = []
    for b in small_town.buildings:
        if b.tower or b.floors < 3:
            continue
        a, u, length = building_side(b.rect, "SENW".index(b.front))
        outward = np.cross(u, [0.0, 0, 1])
        z = (GROUND_FLOOR_M if b.shop else 0.0) + 1.5 * fh  # the middle of the next floor up
        for along in np.arange(2.0, length - 2.0, 1.3):
            eye = a + u * along + outward * 2.0 + np.array([0, 0, z])
            world_from_cam = np.eye(4)
            world_from_cam[:3, :3] = np.stack([u, [0, 0, -1.0], -outward], 1)  # x, y, optical
            world_from_cam[:3, 3] = eye
            depths.append(small_sim.renderer.render_depth(world_from_cam, 32, 24, 60.0).ravel())
        if len(depths) >= 12:
            break
    depth = np.concatenate(depths)
    face = np.mean(np.abs(depth - 2.0) < 0.02)
    window = np.mean(np.abs(depth - 2.0 - WINDOW_RECESS_M) < 0.02)
    assert face > 0.3 and window > 0.1, (face, window)
    assert np.mean((depth > 2.02) & (depth < 2.0 + WINDOW_RECESS_M - 0.02)) < 0.1  # reveals only


def test_a_shop_tile_recurs_only_far_from_itself():
    """Town01 has 8 shop bays per tile: each tile is used once before any twice, and no tile
    comes back within 80 m of itself (90 m measured; scene 6 had the same shop twice on a street)."""
    town = generate_town(load_town_spec("town01"))
    plan = shop_plan(town)
    assert plan == shop_plan(town)  # a pure function of the town
    tiles = [t for k in sorted(plan) for t in plan[k]]
    count = town.spec.buildings.shop_styles
    assert len(tiles) > 4 * count
    assert sorted(tiles[:count]) == list(range(count))
    centres: dict[int, list] = {}
    for k, shops in plan.items():
        for tile, centre in zip(shops, shop_bays(town.buildings[k]), strict=True):
            centres.setdefault(tile, []).append(centre)
    nearest = min(
        np.linalg.norm(p - q) for ps in centres.values() for i, p in enumerate(ps) for q in ps[:i]
    )
    assert nearest > 80.0


def test_a_walls_cells_differ_from_their_neighbours():
    """No cell repeats the 3 before it in its row nor the one below: a repeat one bay over gave
    an answer one bay off that outvoted the truth."""
    rng = np.random.default_rng(0)
    cells = wall_variants(6, 40, 12, rng)
    assert cells.shape == (6, 40) and set(np.unique(cells)) <= set(range(12))
    for gap in (1, 2, 3):
        assert np.all(cells[:, gap:] != cells[:, :-gap])
    assert np.all(cells[1:] != cells[:-1])
    assert np.array_equal(cells, wall_variants(6, 40, 12, np.random.default_rng(0)))
    assert wall_variants(2, 3, 1, rng).tolist() == [[0, 0, 0], [0, 0, 0]]  # no choice
