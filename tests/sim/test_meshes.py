"""Mesh construction: recorded quads; the blocks of the ground textures (paving, grass)."""

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


def _one_quad(origin, u, v, size_u, size_v, uv0, k, nu, nv):
    """A quad made on its own: linspace and meshgrid, as MeshBuilder made each until 2026-12-07."""
    aa, bb = np.meshgrid(np.linspace(0.0, size_u, nu + 1), np.linspace(0.0, size_v, nv + 1))
    verts = origin + aa.reshape(-1, 1) * u + bb.reshape(-1, 1) * v
    uv = np.stack([uv0[0] + aa.ravel() * k[0], uv0[1] + bb.ravel() * k[1]], 1)
    return verts, uv


def test_recorded_quads_come_out_as_made_one_at_a_time_and_in_order():
    """Quads of several subdivisions, between other shapes, come out of :meth:`arrays` with the
    vertices and texture coordinates of each quad made on its own, to the bit, in the order added,
    and with faces that index each quad's own grid (front side along u x v)."""
    rng = np.random.default_rng(4)
    mesh, expected = MeshBuilder(), []
    for n in range(40):
        if n % 7 == 3:  # another shape between the quads
            before = mesh.count
            mesh.cylinder(rng.normal(size=3), 0.2, 3.0)
            expected.append(("other", mesh.count - before))
            continue
        origin, u, v = rng.normal(size=3) * 50, rng.normal(size=3), rng.normal(size=3)
        size_u, size_v = rng.uniform(0.1, 9.0, 2)
        uv0, k = tuple(rng.normal(size=2)), tuple(rng.normal(size=2))
        cell_m = (0.0, 2.0, 0.7)[n % 3]
        nu = max(1, int(np.ceil(size_u / cell_m))) if cell_m else 1
        nv = max(1, int(np.ceil(size_v / cell_m))) if cell_m else 1
        mesh.quad(origin, u, v, size_u, size_v, uv0, k, cell_m)
        made = _one_quad(origin, u, v, size_u, size_v, uv0, k, nu, nv)
        expected.append(("quad", made, u, v, 2 * nu * nv))
    vertices, uvs, faces = mesh.arrays()
    first = 0
    for item in expected:
        if item[0] == "other":
            first += item[1]
            continue
        (verts, uv), u, v, triangles = item[1:]
        rows = slice(first, first + len(verts))
        assert np.array_equal(vertices[rows], verts) and np.array_equal(uvs[rows], uv)
        own = faces[(faces >= first).all(1) & (faces < first + len(verts)).all(1)]
        a, b, c = (vertices[own[:, i]] for i in range(3))
        assert len(own) == triangles
        assert (np.cross(b - a, c - a) @ np.cross(u, v) > 0).all()
        first += len(verts)
    assert first == len(vertices) == mesh.count and faces.max() == len(vertices) - 1
