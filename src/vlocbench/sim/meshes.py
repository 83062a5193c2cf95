"""Triangle-mesh construction for the town (pure numpy).

Lighting in MuJoCo's renderer is per vertex, so surfaces that headlights must light are
subdivided into cells of about ``cell_m`` (2 m). Every face gets its own vertices so that normals and
texture coordinates stay sharp at edges.
"""

from __future__ import annotations

import functools
import itertools
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vlocbench.interfaces import Array

# ground textures are laid in blocks of a world grid, each its own cut of the tile
GROUND_BLOCK_M = 4.0


@dataclass
class MeshBuilder:
    """Accumulates triangles: vertices (N, 3), texture coordinates (N, 2), faces (M, 3).

    Quads are most of a town (about 140,000 in town01), so :meth:`quad` records them and
    :meth:`arrays` makes them in one vectorized pass per subdivision, with the arithmetic of one
    quad at a time (the same arrays to the bit) and in the order everything was added.
    """

    parts: list[tuple[int, int, Array, Array, NDArray[np.int64]]] = field(default_factory=list)
    quads: dict[tuple[int, int], list[tuple[Any, ...]]] = field(default_factory=dict)
    count: int = 0  # vertices so far
    face_count: int = 0

    def add(self, vertices: Array, uvs: Array, faces: NDArray[np.int64]) -> None:
        self.parts.append((self.count, self.face_count, vertices, uvs, faces + self.count))
        self.count += len(vertices)
        self.face_count += len(faces)

    def arrays(self) -> tuple[Array, Array, NDArray[np.int64]]:
        vertices, uvs = np.empty((self.count, 3)), np.empty((self.count, 2))
        faces = np.empty((self.face_count, 3), np.int64)
        for first, first_face, v, uv, f in self.parts:
            vertices[first : first + len(v)], uvs[first : first + len(v)] = v, uv
            faces[first_face : first_face + len(f)] = f
        for (nu, nv), records in self.quads.items():
            origin, u, v, size_u, size_v, uv_origin, uv_per_m, starts, face_starts = (
                np.array(c) for c in zip(*records)
            )
            # np.linspace(0, size, n + 1) of each quad, as linspace computes it
            a = np.arange(nu + 1.0) * (size_u / nu)[:, None]
            b = np.arange(nv + 1.0) * (size_v / nv)[:, None]
            a[:, -1], b[:, -1] = size_u, size_v
            aa = np.tile(a, (1, nv + 1))[..., None]  # (Q, P, 1): meshgrid "xy", raveled
            bb = np.repeat(b, nu + 1, axis=1)[..., None]
            rows = starts[:, None] + np.arange((nu + 1) * (nv + 1))
            vertices[rows] = origin[:, None] + aa * u[:, None] + bb * v[:, None]
            uvs[rows] = np.concatenate(
                [
                    uv_origin[:, None, :1] + aa * uv_per_m[:, None, :1],
                    uv_origin[:, None, 1:] + bb * uv_per_m[:, None, 1:],
                ],
                axis=2,
            )
            template = _quad_faces(nu, nv)
            faces[face_starts[:, None] + np.arange(len(template))] = (
                template + starts[:, None, None]
            )
        return vertices, uvs, faces

    def __bool__(self) -> bool:
        return self.count > 0

    def quad(
        self,
        origin: Array,
        u_axis: Array,
        v_axis: Array,
        size_u: float,
        size_v: float,
        uv_origin: tuple[float, float] = (0.0, 0.0),
        uv_per_m: tuple[float, float] = (1.0, 1.0),
        cell_m: float = 0.0,
    ) -> None:
        """A rectangle ``origin + a*u_axis + b*v_axis``, a in [0, size_u], b in [0, size_v].

        Its front (counter-clockwise) side faces ``u_axis x v_axis``. Texture coordinates grow by
        ``uv_per_m`` per metre from ``uv_origin``; ``cell_m`` > 0 subdivides into cells.
        """
        nu = max(1, int(np.ceil(size_u / cell_m))) if cell_m > 0 else 1
        nv = max(1, int(np.ceil(size_v / cell_m))) if cell_m > 0 else 1
        record = (
            np.asarray(origin, float),
            np.asarray(u_axis, float),
            np.asarray(v_axis, float),
            float(size_u),
            float(size_v),
            tuple(map(float, uv_origin)),
            tuple(map(float, uv_per_m)),
            self.count,
            self.face_count,
        )
        self.quads.setdefault((nu, nv), []).append(record)
        self.count += (nu + 1) * (nv + 1)
        self.face_count += 2 * nu * nv

    def box(self, center: Array, half: Array, yaw_rad: float = 0.0, uv_per_m: float = 0.5) -> None:
        """A closed box (all six faces), rotated by ``yaw_rad`` about z."""
        c, s = np.cos(yaw_rad), np.sin(yaw_rad)
        ex, ey, ez = np.array([c, s, 0.0]), np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0])
        hx, hy, hz = half
        corner = center - hx * ex - hy * ey - hz * ez
        k = (uv_per_m, uv_per_m)
        self.quad(corner, ex, ez, 2 * hx, 2 * hz, uv_per_m=k)  # -y face
        self.quad(corner + 2 * hy * ey + 2 * hx * ex, -ex, ez, 2 * hx, 2 * hz, uv_per_m=k)
        self.quad(corner + 2 * hy * ey, -ey, ez, 2 * hy, 2 * hz, uv_per_m=k)  # -x face
        self.quad(corner + 2 * hx * ex, ey, ez, 2 * hy, 2 * hz, uv_per_m=k)
        self.quad(corner + 2 * hz * ez, ex, ey, 2 * hx, 2 * hy, uv_per_m=k)  # top
        self.quad(corner + 2 * hy * ey, ex, -ey, 2 * hx, 2 * hy, uv_per_m=k)  # bottom

    def cylinder(
        self,
        base: Array,
        radius: float,
        height: float,
        sides: int = 8,
        top_radius: float | None = None,
    ) -> None:
        """An open-ended vertical (truncated) cone/cylinder standing on ``base``."""
        top_radius = radius if top_radius is None else top_radius
        a = np.linspace(0.0, 2 * np.pi, sides + 1)
        ring = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], 1)
        bottom = base + radius * ring
        top = base + top_radius * ring + np.array([0.0, 0.0, height])
        verts = np.concatenate([bottom, top])
        uv = np.stack([np.tile(a / np.pi, 2), np.repeat([0.0, height], sides + 1)], 1)
        i = np.arange(sides)
        n = sides + 1
        faces = np.concatenate(
            [np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)]
        )
        self.add(verts, uv, faces)

    def blob(self, center: Array, radii: Array, rng: np.random.Generator, subdiv: int = 1) -> None:
        """A lumpy ellipsoid (icosphere with radial noise), e.g. a tree crown."""
        verts, faces = icosphere(subdiv)
        verts = verts * (1 + rng.uniform(-0.12, 0.12, (len(verts), 1)))
        uv = np.stack([np.arctan2(verts[:, 1], verts[:, 0]), verts[:, 2]], 1) * 1.5
        self.add(center + verts * radii, uv, faces)


@functools.cache
def _quad_faces(nu: int, nv: int) -> NDArray[np.int64]:
    """The triangles (2 nu nv, 3) of a quad's (nv + 1) x (nu + 1) grid of vertices, row-major."""
    idx = np.arange((nv + 1) * (nu + 1)).reshape(nv + 1, nu + 1)
    p00, p10 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    p01, p11 = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)])
    faces.flags.writeable = False
    return faces


def icosphere(subdiv: int) -> tuple[Array, NDArray[np.int64]]:
    """Unit icosphere: vertices (N, 3), outward counter-clockwise faces (M, 3)."""
    t = (1 + 5**0.5) / 2
    verts = [
        [-1, t, 0],
        [1, t, 0],
        [-1, -t, 0],
        [1, -t, 0],
        [0, -1, t],
        [0, 1, t],
        [0, -1, -t],
        [0, 1, -t],
        [t, 0, -1],
        [t, 0, 1],
        [-t, 0, -1],
        [-t, 0, 1],
    ]
    faces = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ]
    v = [np.array(p, dtype=np.float64) / np.linalg.norm(p) for p in verts]
    f = faces
    for _ in range(subdiv):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = v[a] + v[b]
                v.append(m / np.linalg.norm(m))
                cache[key] = len(v) - 1
            return cache[key]

        new = []
        for a, b, c in f:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = new
    return np.array(v), np.array(f, dtype=np.int64)


def corner_arcs(
    rect: tuple[float, float, float, float], radius: float, step_m: float
) -> list[tuple[tuple[float, float], Array]]:
    """The four rounded corners of ``rect``, counter-clockwise: (centre, arc points (N, 2))."""
    x0, y0, x1, y1 = rect
    n = max(3, int(np.ceil(0.5 * np.pi * radius / step_m)))
    out = []
    for cx, cy, a0 in (
        (x1 - radius, y0 + radius, -np.pi / 2),
        (x1 - radius, y1 - radius, 0.0),
        (x0 + radius, y1 - radius, np.pi / 2),
        (x0 + radius, y0 + radius, np.pi),
    ):
        a = a0 + np.linspace(0, np.pi / 2, n + 1)
        out.append(((cx, cy), np.stack([cx + radius * np.cos(a), cy + radius * np.sin(a)], 1)))
    return out


def rounded_rect_outline(
    rect: tuple[float, float, float, float], radius: float, step_m: float = 1.0
) -> Array:
    """Counter-clockwise outline (N, 2) of a rectangle with rounded corners (not closed)."""
    x0, y0, x1, y1 = rect
    if radius <= 0:
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
    pts = [arc for _, arc in corner_arcs(rect, radius, step_m)]
    return np.concatenate(pts)


def platform_mesh(
    top: MeshBuilder,
    side: MeshBuilder,
    rect: tuple[float, float, float, float],
    radius: float,
    height: float,
    cell_m: float,
    tile_m: float,
    slab_m: float,
) -> None:
    """A raised slab: its top (subdivided, rounded corners as fans) and its curb faces."""
    _platform_top(top, rect, radius, height, cell_m, tile_m, slab_m)
    _curb_faces(side, rect, radius, height, cell_m)


def _platform_top(
    top: MeshBuilder,
    rect: tuple[float, float, float, float],
    r: float,
    height: float,
    cell_m: float,
    tile_m: float,
    slab_m: float,
) -> None:
    """A cross-shaped body (centre column plus the two side columns) and a fan per corner."""
    x0, y0, x1, y1 = rect
    laid_in_blocks(top, (x0 + r, y0, x1 - r, y1), height, cell_m, tile_m, slab_m)
    if r <= 0:
        return
    for xa in (x0, x1 - r):
        laid_in_blocks(top, (xa, y0 + r, xa + r, y1 - r), height, cell_m, tile_m, slab_m)
    for (cx, cy), arc in corner_arcs(rect, r, 1.0):
        n = len(arc) - 1
        ring = np.concatenate([arc, np.full((n + 1, 1), height)], axis=1)
        verts = np.concatenate([[[cx, cy, height]], ring])
        faces = np.stack([np.zeros(n, np.int64), np.arange(1, n + 1), np.arange(2, n + 2)], 1)
        top.add(verts, verts[:, :2] / tile_m, faces)


def laid_in_blocks(
    top: MeshBuilder,
    rect: tuple[float, float, float, float],
    z_m: float,
    cell_m: float,
    tile_m: float,
    step_m: float,
    mirror: bool = False,
    block_m: float = GROUND_BLOCK_M,
) -> None:
    """A horizontal rectangle in the blocks of a ``block_m`` world grid, each block's texture moved
    by whole ``step_m`` (a paving slab: slab edges still meet) and, with ``mirror``, mirrored along
    either axis, a pure function of the block's index. A texture laid straight repeats every
    ``tile_m``, and a localizer matched the repeats: the sidewalks' 16 m on (noon answers in the
    wrong place), the grass's 4 m (ghost points behind the parks; docs/reproduction.md)."""
    x0, y0, x1, y1 = rect
    steps = round(tile_m / step_m)
    for xa, xb in itertools.pairwise(_grid_cuts(x0, x1, block_m)):
        for ya, yb in itertools.pairwise(_grid_cuts(y0, y1, block_m)):
            block = np.floor(np.array([xa + xb, ya + yb]) / (2 * block_m)).astype("<i8")
            h = zlib.crc32(block.tobytes())
            du, dv = (h % steps) * step_m, ((h >> 16) % steps) * step_m
            # bits 8 and 24: the shifts do not read them while steps is a power of two <= 256
            su, sv = (-1.0 if mirror and (h >> bit) & 1 else 1.0 for bit in (8, 24))
            top.quad(
                np.array([xa, ya, z_m]),
                np.array([1.0, 0, 0]),
                np.array([0, 1.0, 0]),
                xb - xa,
                yb - ya,
                (su * (xa + du) / tile_m, sv * (ya + dv) / tile_m),
                (su / tile_m, sv / tile_m),
                cell_m,
            )


def _grid_cuts(lo: float, hi: float, step: float) -> list[float]:
    """``lo``, the multiples of ``step`` strictly between ``lo`` and ``hi``, and ``hi``."""
    inner = np.arange(np.floor(lo / step) + 1, np.ceil(hi / step)) * step
    return [lo, *(float(v) for v in inner if lo < v < hi), hi]


def _curb_faces(
    side: MeshBuilder,
    rect: tuple[float, float, float, float],
    r: float,
    height: float,
    cell_m: float,
) -> None:
    """The vertical faces along the rounded outline, subdivided: fog and lighting are computed
    per vertex."""
    outline = rounded_rect_outline(rect, r)
    closed = np.concatenate([outline, outline[:1]])
    for a, b in itertools.pairwise(closed):
        d = b - a
        length = float(np.linalg.norm(d))
        if length < 1e-6:
            continue
        u = np.array([d[0], d[1], 0.0]) / length
        side.quad(
            np.array([a[0], a[1], 0.0]),
            u,
            np.array([0, 0, 1.0]),
            length,
            height,
            uv_per_m=(1.0, 1.0),
            cell_m=cell_m,
        )
