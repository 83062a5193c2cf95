"""Mesh construction: the sidewalks' blocks of paving."""

import numpy as np

from vlocbench.sim.meshes import PAVING_BLOCK_M, MeshBuilder, platform_mesh


def test_paving_blocks_are_whole_slab_cuts_of_the_tile():
    """Every block of a sidewalk shows the tile moved by whole slabs (its slab edges meet its
    neighbours'), and blocks along a street take different cuts: the 16 m tile no longer repeats."""
    top, side = MeshBuilder(), MeshBuilder()
    tile_m, slab_m = 16.0, 0.5
    platform_mesh(top, side, (-3.0, 1.0, 61.0, 4.0), 0.0, 0.15, 2.0, tile_m, slab_m)
    vertices, uvs, _ = top.arrays()
    assert np.allclose(vertices[:, 2], 0.15)
    shift_slabs = (uvs * tile_m - vertices[:, :2]) / slab_m
    assert np.allclose(shift_slabs, np.round(shift_slabs))
    blocks = np.floor(vertices[:, 0] / PAVING_BLOCK_M - 1e-9)
    shifts = {tuple(np.round(s)) for s in shift_slabs}
    assert len(shifts) >= 0.8 * len(np.unique(blocks))
    assert np.isclose(np.ptp(vertices[:, 0]), 64.0) and np.isclose(np.ptp(vertices[:, 1]), 3.0)
