"""Mesh construction: the blocks the ground textures are laid in (paving, grass)."""

import numpy as np

from vlocbench.sim.meshes import GROUND_BLOCK_M, MeshBuilder, laid_in_blocks, platform_mesh


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
    blocks = np.floor(vertices[:, 0] / GROUND_BLOCK_M - 1e-9)
    shifts = {tuple(np.round(s)) for s in shift_slabs}
    assert len(shifts) >= 0.8 * len(np.unique(blocks))
    assert np.isclose(np.ptp(vertices[:, 0]), 64.0) and np.isclose(np.ptp(vertices[:, 1]), 3.0)


def test_grass_blocks_are_mirrored_and_moved_cuts_of_the_tile():
    """Mirrored along either axis and moved, each block shows its own cut of the 16 m grass tile:
    no block looks like its neighbours, and the texture keeps its scale (16 m a tile)."""
    top = MeshBuilder()
    tile_m, block_m = 16.0, 4.0
    laid_in_blocks(top, (0.0, 0.0, 64.0, 64.0), 0.2, block_m, tile_m, tile_m / 64, mirror=True)
    vertices, uvs, _ = top.arrays()
    # one cell a block: its corners (0, 0), (4, 0), (0, 4), (4, 4) m
    corners, tex = vertices.reshape(-1, 4, 3), uvs.reshape(-1, 4, 2)
    assert len(corners) == 16 * 16 and np.allclose(vertices[:, 2], 0.2)
    scale = np.stack([tex[:, 1, 0] - tex[:, 0, 0], tex[:, 2, 1] - tex[:, 0, 1]], 1) / block_m
    assert np.allclose(np.abs(scale), 1 / tile_m)
    assert len({tuple(s) for s in np.sign(scale)}) == 4  # every mirroring occurs
    cut = {
        tuple(np.floor(c[0, :2] / block_m).astype(int)): (*np.sign(s), *np.round(t[0] % 1, 6))
        for c, s, t in zip(corners, scale, tex, strict=True)
    }
    for (i, j), look in cut.items():
        for n in ((i + 1, j), (i, j + 1)):
            assert n not in cut or cut[n] != look
