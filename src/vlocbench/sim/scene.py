"""The MuJoCo model of a town: merged textured meshes to draw, primitives to collide with.

Static geometry is merged into one mesh per material (few draw calls keep llvmpipe fast); for
collisions every building, trunk, pole, parked car and sidewalk slab, and a wall around the town's
extent, is a primitive (box/cylinder) in geom group 4, which cameras never draw. The ego car is a
free body (geom group 5, hidden from its own cameras) carrying two headlight spots; traffic cars
and pedestrians are free bodies in group 3.

Collision filtering: static geoms have contype 0, conaffinity 1; the ego has contype 1, conaffinity 0;
so only ego-vs-world and ego-vs-traffic pairs are ever tested.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from vlocbench.interfaces import Array
from vlocbench.sim import textures as tex
from vlocbench.sim.meshes import GROUND_BLOCK_M, MeshBuilder, laid_in_blocks, platform_mesh
from vlocbench.sim.town import Building, Town

GROUP_STATIC, GROUP_FOLIAGE_FULL, GROUP_FOLIAGE_SPARSE = 0, 1, 2
GROUP_TRAFFIC, GROUP_COLLISION, GROUP_EGO = 3, 4, 5
# meshes of the town's lights at night (lamp heads, lit windows): parked this far below the town
# by day, so that day images do not change with them
NIGHT_MESHES = ("lamp_glow", "windows_lit")
NIGHT_PARKED_Z_M = -1000.0
LAMP_HEIGHT_M = 6.2  # the underside of a lamp's head, where its light leaves
LAMP_REACH_M = 1.7  # from the pole to the head, towards the road
# bump when the look of the towns changes: galleries and maps (and results) are keyed by it
# 7: window relief, shop tiles apart, paving in shifted blocks; 8: grass 16 m in blocks
SCENE_VERSION = 8
EDGE_WALL_M, EDGE_HEIGHT_M = 2.0, 3.0  # the town's edge: a wall just outside its extent
GROUND_FLOOR_M = 4.2
GROUND_SHIFTS = 64  # the moves a ground block's texture may take, per tile (a power of two)
LOW_WALL_M = 12.0  # walls below: vertices every cell_m (headlights), windows set back
SHOP_ATLAS_COLUMNS = 8
SKY_SIZE = 64
CAR_HALF_M = (2.3, 0.95)  # half length, half width of every car (ego, traffic, parked)
CAR_COLORS = (
    (0.75, 0.08, 0.08),
    (0.1, 0.2, 0.6),
    (0.85, 0.85, 0.85),
    (0.1, 0.1, 0.1),
    (0.5, 0.5, 0.52),
    (0.9, 0.7, 0.1),
    (0.15, 0.45, 0.2),
    (0.55, 0.3, 0.15),
)
FACADE_TINTS = ((1.0, 1.0, 1.0), (0.9, 0.93, 1.0), (1.0, 0.92, 0.85))
SEASON_MATERIALS = ("ground", "paving", "road", "roof", "grass")
GROUND_KINDS = (
    "grass",
    "autumn_grass",
    "sand",
    "water",
    "roof",
    "bark",
    "leaves",
    "concrete",
    "metal",
)


@dataclass(frozen=True)
class SceneOptions:
    """Build-time options. ``max_cars``/``max_pedestrians``: traffic slots (free bodies)."""

    max_cars: int = 0
    max_pedestrians: int = 0
    cell_m: float = 2.0  # vertex spacing of lit surfaces (per-vertex lighting)
    max_image_size: int = 2048  # largest render width/height


@dataclass
class TownScene:
    """A compiled town. ``geom_info[geom_id] = (category, label)`` for collidable geoms."""

    town: Town
    options: SceneOptions
    model: mujoco.MjModel
    data: mujoco.MjData
    geom_info: dict[int, tuple[str, str]]
    season_geoms: dict[str, list[int]]  # material family -> geoms whose material follows seasons
    material_ids: dict[str, int]
    sky_texture_id: int
    sun_light_id: int
    headlight_ids: tuple[int, int]
    night_geom_ids: tuple[int, ...]  # the NIGHT_MESHES geoms
    window_texture_id: int
    ego_qpos_adr: int
    car_qpos_adr: tuple[int, ...]
    pedestrian_qpos_adr: tuple[int, ...]
    base_rgba: dict[str, Array] = field(default_factory=dict)

    def set_free_pose(
        self, qpos_adr: int, x_m: float, y_m: float, yaw_rad: float, z_m: float = 0.0
    ) -> None:
        q = self.data.qpos
        q[qpos_adr : qpos_adr + 3] = (x_m, y_m, z_m)
        q[qpos_adr + 3 : qpos_adr + 7] = (np.cos(yaw_rad / 2), 0.0, 0.0, np.sin(yaw_rad / 2))

    def forward(self) -> None:
        """Recompute positions of bodies, geoms, cameras and lights from ``data.qpos``."""
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)


class _SceneBuilder:
    def __init__(self, town: Town, options: SceneOptions) -> None:
        self.town = town
        self.options = options
        self.rng = np.random.default_rng(town.spec.seed + 7919)
        self.spec = mujoco.MjSpec()
        self.meshes: dict[str, MeshBuilder] = defaultdict(MeshBuilder)
        self.mesh_group: dict[str, int] = {}
        self.materials: set[str] = set()
        self.tiles: dict[str, tex.FacadeTile] = {}
        self.collision: list[tuple[str, str]] = []  # (category, label) per collision geom, in order

    # -- assets ---------------------------------------------------------------------------------
    def texture(self, name: str, image: NDArray[np.uint8]) -> None:
        t = self.spec.add_texture(name=name, type=mujoco.mjtTexture.mjTEXTURE_2D)
        h, w = image.shape[:2]
        t.width, t.height, t.nchannel = w, h, 3
        t.data = np.ascontiguousarray(image).tobytes()

    def material(
        self,
        name: str,
        texture: str | None,
        rgba: tuple[float, ...] = (1, 1, 1, 1),
        specular: float = 0.1,
        shininess: float = 0.1,
        emission: float = 0.0,
        texrepeat: float = 1.0,
    ) -> None:
        """``texrepeat``: the texture's repeats per unit of the meshes' texture coordinates."""
        m = self.spec.add_material(name=name)
        if texture is not None:
            m.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = texture
            m.texrepeat = [texrepeat, texrepeat]
        m.rgba = list(rgba) if len(rgba) == 4 else [*rgba, 1.0]
        m.specular, m.shininess, m.emission = specular, shininess, emission
        self.materials.add(name)

    def make_assets(self) -> None:
        """Textures and materials, drawn from the scene's generator in a fixed order (buildings,
        then ground and props), so that a town always looks the same."""
        self._building_assets()
        self._ground_assets()
        self._season_materials()
        self._object_materials()
        sky = self.spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX)
        sky.width, sky.height, sky.nchannel = SKY_SIZE, 6 * SKY_SIZE, 3
        sky.data = tex.sky((0.35, 0.55, 0.85), (0.75, 0.82, 0.9), SKY_SIZE).tobytes()

    def _building_assets(self) -> None:
        """Facade styles (each in FACADE_TINTS), tower glass, and every shopfront in one atlas
        texture: one material, one mesh, however many shops."""
        spec, rng = self.town.spec, self.rng
        fh = spec.buildings.floor_height_m
        for s in range(spec.buildings.facade_styles):
            style = s if spec.style == "town" else (s * 2 + 1) % 4  # cities: stone/concrete/plaster
            tile = tex.facade(style, fh, rng)
            self.tiles[f"facade{s}"] = tile
            self.texture(f"facade{s}", tile.image)
            for k, tint in enumerate(FACADE_TINTS):
                self.material(f"facade{s}_{k}", f"facade{s}", tint, specular=0.15)
        for s in range(3):
            tile = tex.facade(4, fh, rng)
            self.tiles[f"tower{s}"] = tile
            self.texture(f"tower{s}", tile.image)
            self.material(f"tower{s}", f"tower{s}", specular=0.5, shininess=0.6)
        shops = [
            tex.shopfront(s + 6 * spec.seed, GROUND_FLOOR_M, rng)
            for s in range(spec.buildings.shop_styles)
        ]
        self.shop_columns = min(len(shops), SHOP_ATLAS_COLUMNS)
        self.shop_rows = -(-len(shops) // self.shop_columns)
        self.texture("shops", tex.atlas([t.image for t in shops], self.shop_columns))
        self.material("shops", "shops", specular=0.2)

    def _ground_assets(self) -> None:
        """Road, asphalt, crosswalk, paving (and their winter forms), ground kinds, signs."""
        spec, rng = self.town.spec, self.rng
        road = tex.road_tile(spec.road.lane_width_m, 12.0, rng, spec.road.lanes_per_direction)
        self.texture("road", road)
        self.texture("road_winter", tex.snowy_road(road, rng))
        asphalt = tex._finish(tex.asphalt(256, rng), rng, 4)
        self.texture("asphalt", asphalt)
        self.texture("asphalt_winter", tex.snowy_road(asphalt, rng))
        self.texture("crosswalk", tex.crosswalk_tile(rng))
        self.texture("paving", tex.paving(rng))
        self.texture("paving_winter", tex.paving(rng, snow=0.8))
        for kind in GROUND_KINDS:
            self.texture(kind, tex.ground(kind, rng))
        self.texture("snow", tex.ground("concrete", rng, snow=1.2))
        self.texture("signs", tex.sign_atlas(rng))

    def _season_materials(self) -> None:
        """Each surface family in summer, autumn and winter dress."""
        for family in SEASON_MATERIALS:
            base = {
                "ground": "grass",
                "paving": "paving",
                "road": "road",
                "roof": "roof",
                "grass": "grass",
            }[family]
            self.material(family, base, specular=0.05)
            autumn = {"ground": "autumn_grass", "grass": "autumn_grass"}.get(family, base)
            self.material(f"{family}_autumn", autumn, specular=0.05)
            winter = {"road": "road_winter", "paving": "paving_winter"}.get(family, "snow")
            # the snow's 4 m tile on surfaces laid for grass's larger one keeps its own size
            repeat = (
                tex.ground_tile_m(base) / tex.ground_tile_m("concrete") if winter == "snow" else 1
            )
            self.material(f"{family}_winter", winter, specular=0.2, texrepeat=repeat)
        self.material("intersection", "asphalt", specular=0.05)
        self.material("intersection_winter", "asphalt_winter", specular=0.2)
        self.material("intersection_autumn", "asphalt", specular=0.05)

    def _object_materials(self) -> None:
        self.material("crosswalk", "crosswalk", specular=0.05)
        self.material("curb", "concrete")
        self.material("sand", "sand")
        self.material("water", "water", specular=0.8, shininess=0.9)
        self.material("bark", "bark")
        self.material("leaves_full", "leaves", (0.33, 0.55, 0.22, 1))
        self.material("leaves_sparse", "leaves", (0.33, 0.55, 0.22, 1))
        self.material("metal", "metal", specular=0.4, shininess=0.5)
        self.material("signs", "signs", specular=0.3)
        self.material("glass", None, (0.08, 0.1, 0.12, 1), specular=0.8, shininess=0.9)
        # the town's lights at night: a lamp's diffuser glows at any exposure; a lit window's
        # glow is set by the renderer, its texture lights the share of windows asked for
        self.material("lamp_glow", None, (1.0, 0.92, 0.75, 1), specular=0.0, emission=1.0)
        self.texture("windows_lit", tex.lit_windows(0.0))
        self.material("windows_lit", "windows_lit", specular=0.0)
        for k, c in enumerate(CAR_COLORS):
            self.material(f"car{k}", None, c, specular=0.6, shininess=0.7)

    # -- geometry -------------------------------------------------------------------------------
    def collide_box(
        self, category: str, label: str, center: Array, half: Array, yaw: float = 0.0
    ) -> None:
        self.spec.worldbody.add_geom(
            name=f"col{len(self.collision)}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=list(center),
            quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)],
            size=list(half),
            group=GROUP_COLLISION,
            contype=0,
            conaffinity=1,
            rgba=[1, 0, 0, 0],
        )
        self.collision.append((category, label))

    def collide_cylinder(
        self, category: str, label: str, x: float, y: float, radius: float, height: float
    ) -> None:
        self.spec.worldbody.add_geom(
            name=f"col{len(self.collision)}",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            pos=[x, y, height / 2],
            size=[radius, height / 2, 0],
            group=GROUP_COLLISION,
            contype=0,
            conaffinity=1,
            rgba=[1, 0, 0, 0],
        )
        self.collision.append((category, label))

    def edge(self) -> None:
        """The town's edge: a wall around its extent to collide with, never drawn. CARLA's towns
        end in terrain, trees and fences, where a lost car crashes; past ours lies open ground,
        on which a car whose filter is lost drove on for hundreds of metres without a failure."""
        x0, y0, x1, y1 = self.town.extent
        t, h = EDGE_WALL_M / 2, EDGE_HEIGHT_M / 2  # half its thickness and height
        cx, cy, hx, hy = (x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0) / 2 + EDGE_WALL_M, (y1 - y0) / 2
        for side, center, half in (
            ("south", (cx, y0 - t, h), (hx, t, h)),
            ("north", (cx, y1 + t, h), (hx, t, h)),
            ("west", (x0 - t, cy, h), (t, hy, h)),
            ("east", (x1 + t, cy, h), (t, hy, h)),
        ):
            self.collide_box("edge", f"the {side} edge", np.array(center), np.array(half))

    def roads(self) -> None:
        town = self.town
        lay = town.layout
        hw, zone, cell = lay.half_width_m, lay.zone_m, self.options.cell_m
        z = np.array([0, 0, 0.02])
        tile_len = 12.0
        for i in range(len(lay.xs)):
            for j in range(len(lay.ys)):
                c = np.array([lay.xs[i], lay.ys[j], 0.0])
                self.meshes["intersection"].quad(
                    c + np.array([-zone, -zone, 0]) + z,
                    np.array([1.0, 0, 0]),
                    np.array([0, 1.0, 0]),
                    2 * zone,
                    2 * zone,
                    ((c[0] - zone) / 4, (c[1] - zone) / 4),
                    (0.25, 0.25),
                    cell,
                )
                for di, dj in ((1, 0), (0, 1)):
                    if i + di >= len(lay.xs) or j + dj >= len(lay.ys):
                        continue
                    b = np.array([lay.xs[i + di], lay.ys[j + dj], 0.0])
                    h = (b - c) / np.linalg.norm(b - c)
                    right = np.array([h[1], -h[0], 0.0])
                    length = float(np.linalg.norm(b - c)) - 2 * zone
                    start = c + h * zone - right * hw + z
                    self.meshes["road"].quad(
                        start,
                        right,
                        h,
                        2 * hw,
                        length,
                        (0.0, 0.0),
                        (1 / (2 * hw), 1 / tile_len),
                        cell,
                    )
                    for end, direction in ((start, h), (start + h * length, -h)):
                        if self.rng.random() < 0.5:
                            o = (
                                end
                                + direction * (3.0 if direction @ h < 0 else 0.0)
                                + np.array([0, 0, 0.005])
                            )
                            self.meshes["crosswalk"].quad(
                                o, right, h, 2 * hw, 3.0, (0, 0), (1 / 4, 1 / 4), cell
                            )

    def ground(self) -> None:
        x0, y0, x1, y1 = self.town.extent
        m = 300.0
        # the open ground, grass: in 16 m blocks, 20 m cells (what the fog needs) as before
        rect = (x0 - m, y0 - m, x1 + m, y1 + m)
        self.flat("ground", rect, 0.0, tex.ground_tile_m("grass"), cell_m=20.0, block_m=16.0)
        for rect in self.town.sand:
            self.flat("sand", rect, 0.01, tex.ground_tile_m("sand"))
        for rect in self.town.water:
            self.flat("water", rect, 0.005, 8.0)

    def flat(
        self,
        material: str,
        rect: tuple[float, float, float, float],
        z: float,
        tile_m: float,
        cell_m: float | None = None,
        block_m: float = GROUND_BLOCK_M,
    ) -> None:
        """A horizontal ground texture over ``rect``, in mirrored blocks each moved by one of
        ``GROUND_SHIFTS`` steps of its tile; cells of ``cell_m`` (the scene's by default)."""
        cell_m = self.options.cell_m if cell_m is None else cell_m
        step_m = tile_m / GROUND_SHIFTS
        laid_in_blocks(self.meshes[material], rect, z, cell_m, tile_m, step_m, True, block_m)

    def platforms(self) -> None:
        h = self.town.spec.road.curb_height_m
        for k, p in enumerate(self.town.platforms):
            platform_mesh(
                self.meshes["paving"],
                self.meshes["curb"],
                p.rect,
                p.corner_radius_m,
                h,
                self.options.cell_m,
                tex.PAVING_TILE_M,
                tex.PAVING_SLAB_M,
            )
            for rect in _slab_boxes(p.rect, p.corner_radius_m):
                bx0, by0, bx1, by1 = rect
                c = np.array([(bx0 + bx1) / 2, (by0 + by1) / 2, h / 2])
                self.collide_box(
                    "curb", f"sidewalk {k}", c, np.array([(bx1 - bx0) / 2, (by1 - by0) / 2, h / 2])
                )
        for rect in self.town.grass:
            self.flat("grass", rect, h + 0.01, tex.ground_tile_m("grass"))

    def shopfronts(self, origin: Array, u: Array, length_m: float, shops: list[int]) -> None:
        """A row of shops along a ground floor, ``shops`` its atlas tiles from ``origin``."""
        seg = length_m / len(shops)
        cols, rows = self.shop_columns, self.shop_rows
        for j, shop in enumerate(shops):
            r, c = divmod(shop, cols)
            self.meshes["shops"].quad(
                origin + u * (j * seg),
                u,
                np.array([0.0, 0, 1]),
                seg,
                GROUND_FLOOR_M,
                (c / cols, (r + 1) / rows),
                (1 / (cols * seg), -1 / (rows * GROUND_FLOOR_M)),
                self.options.cell_m,
            )

    def facade_wall(
        self,
        material: str,
        tile: tex.FacadeTile,
        origin: Array,
        u: Array,
        length_m: float,
        z_range_m: tuple[float, float],
        rng: np.random.Generator,
        lit: np.random.Generator,
    ) -> None:
        """A wall of one-bay x one-floor cells, each a random variant of the style's atlas
        (``wall_variants``); ``lit`` draws which of its full-height cells have a window lit at
        night."""
        up = np.array([0.0, 0, 1])
        normal = np.cross(u, up)  # out of the building: the quads face it
        n = max(1, round(length_m / tile.width_m))
        bay_m = length_m / n  # whole bays: windows never cut at a corner
        z, top = z_range_m
        floor_z = []  # the bottom of each floor's cells
        while z < top - 1e-6:
            floor_z.append(z)
            z += tile.height_m
        variants = wall_variants(len(floor_z), n, tile.variants, rng)
        for row, z in enumerate(floor_z):
            height = min(tile.height_m, top - z)
            # lower walls: fine cells for headlights, and relief (upper floors are seen far and
            # steep, and their relief cost a third more draw time in town10)
            low = z < LOW_WALL_M
            cell = self.options.cell_m if low else 0.0
            for j in range(n):
                variant = int(variants[row, j])
                corner = origin + u * (j * bay_m) + up * z
                whole = tile.window is not None and height == tile.height_m
                relief = whole and low
                self.facade_cell(
                    material, tile, corner, u, -normal, bay_m, height, variant, cell, relief
                )
                if whole:
                    set_back_m = tile.recess_m if relief else 0.0
                    self.lit_window(tile, corner, u, normal, bay_m, set_back_m, lit)

    def facade_cell(
        self,
        material: str,
        tile: tex.FacadeTile,
        corner: Array,
        u: Array,
        inward: Array,
        bay_m: float,
        height_m: float,
        variant: int,
        cell_m: float,
        relief: bool,
    ) -> None:
        """Atlas cell ``variant`` on the wall from ``corner`` (its bottom left) along ``u``,
        ``inward`` the wall's normal into the building (up x u). With
        ``relief``, a whole cell of a style with relief is the wall around its window, the window
        ``tile.recess_m`` behind it, and the four reveals between them (the window's edge texels
        drawn across the depth); the texture lands where a flat cell would put it. Only the
        cell-wide strips are cut into ``cell_m`` cells: the window's edges already cut the rest."""
        up = np.array([0.0, 0, 1])
        mesh = self.meshes[material]
        k = (1 / (tile.variants * bay_m), -1 / tile.height_m)  # texture per metre along u, up
        u0 = variant / tile.variants

        def uv(a_m: float, b_m: float) -> tuple[float, float]:
            return (u0 + a_m * k[0], 1.0 + b_m * k[1])

        def face(a0: float, b0: float, a1: float, b1: float, depth_m: float = 0.0) -> None:
            o = corner + u * a0 + up * b0 + inward * depth_m
            cells = cell_m if a1 - a0 == bay_m else 0.0
            mesh.quad(o, u, up, a1 - a0, b1 - b0, uv(a0, b0), k, cells)

        if not relief or tile.window is None or tile.recess_m <= 0:
            face(0.0, 0.0, bay_m, height_m)
            return
        left, top, right, bottom = tile.window
        a0, a1 = left * bay_m, right * bay_m
        b0, b1 = (1 - bottom) * tile.height_m, (1 - top) * tile.height_m
        d = tile.recess_m
        face(0.0, 0.0, bay_m, b0)  # under the window
        face(0.0, b1, bay_m, height_m)  # over it
        face(0.0, b0, a0, b1)  # beside it
        face(a1, b0, bay_m, b1)
        face(a0, b0, a1, b1, d)  # the window, set back
        at = corner + up * b0
        mesh.quad(at + u * a0, inward, up, d, b1 - b0, uv(a0, b0), (0.0, k[1]))  # left reveal
        mesh.quad(at + u * a1 + inward * d, -inward, up, d, b1 - b0, uv(a1, b0), (0.0, k[1]))
        mesh.quad(at + u * a0, u, inward, a1 - a0, d, uv(a0, b0), (k[0], 0.0))  # sill
        lintel = corner + up * b1 + u * a0 + inward * d
        mesh.quad(lintel, u, -inward, a1 - a0, d, uv(a0, b1), (k[0], 0.0))

    def lit_window(
        self,
        tile: tex.FacadeTile,
        corner: Array,
        u: Array,
        normal: Array,
        bay_m: float,
        set_back_m: float,
        lit: np.random.Generator,
    ) -> None:
        """The window of the cell whose bottom-left is ``corner``, as a quad 2 cm in front of it
        (of the window, ``set_back_m`` behind the wall's face), for the share of windows that are
        lit at night (a rank in [0, 1) per window: the renderer lights those under
        ``StreetLights.window_share``, encoded in the texture coordinate u)."""
        assert tile.window is not None
        left, top, right, bottom = tile.window
        rank = float(lit.random())
        up = np.array([0.0, 0, 1])
        origin = corner + u * (left * bay_m) + up * ((1 - bottom) * tile.height_m)
        origin = origin + normal * (0.02 - set_back_m)
        self.meshes["windows_lit"].quad(
            origin,
            u,
            up,
            (right - left) * bay_m,
            (bottom - top) * tile.height_m,
            (rank, 0.5),
            (0.0, 0.0),
        )

    def buildings(self) -> None:
        shops = shop_plan(self.town)
        for k, b in enumerate(self.town.buildings):
            x0, y0, x1, y1 = b.rect
            facade = f"tower{b.facade % 3}" if b.tower else f"facade{b.facade}"
            mat = facade if b.tower else f"{facade}_{b.tint}"
            tile = self.tiles[facade]
            # this building's own sequence of window cells
            cells = np.random.default_rng((self.town.spec.seed, k))
            lit = np.random.default_rng((self.town.spec.seed, k, 1))  # which windows are lit
            for s in range(4):
                a, u, length = building_side(b.rect, s)
                z0 = 0.0
                if k in shops and "SENW"[s] == b.front:
                    self.shopfronts(a, u, length, shops[k])
                    z0 = GROUND_FLOOR_M
                self.facade_wall(mat, tile, a, u, length, (z0, b.height_m), cells, lit)
            self.meshes["roof"].quad(
                np.array([x0, y0, b.height_m]),
                np.array([1.0, 0, 0]),
                np.array([0, 1.0, 0]),
                x1 - x0,
                y1 - y0,
                (x0 / 4, y0 / 4),
                (0.25, 0.25),
                8.0,
            )
            center = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 2.0])
            self.collide_box(
                "building", f"building {k}", center, np.array([(x1 - x0) / 2, (y1 - y0) / 2, 2.0])
            )

    def props(self) -> None:
        town, rng = self.town, self.rng
        for k, (x, y, trunk_h, crown_r) in enumerate(town.trees):
            base = np.array([x, y, 0.0])
            self.meshes["bark"].cylinder(base, 0.18, trunk_h + crown_r, 6, top_radius=0.08)
            for _ in range(3):  # bare branches, seen in winter
                a = rng.uniform(0, 2 * np.pi)
                tip = base + np.array(
                    [np.cos(a) * crown_r * 0.8, np.sin(a) * crown_r * 0.8, trunk_h + crown_r * 1.2]
                )
                start = base + np.array([0, 0, trunk_h * 0.9])
                self.meshes["bark"].add(*_branch(start, tip, 0.06))
            center = base + np.array([0, 0, trunk_h + crown_r * 0.9])
            radii = np.array([crown_r, crown_r, crown_r * 1.1])
            self.meshes["leaves_full"].blob(center, radii, rng)
            self.meshes["leaves_full"].blob(
                center + rng.uniform(-0.6, 0.6, 3) * crown_r, radii * 0.7, rng
            )
            self.meshes["leaves_sparse"].blob(center, radii * 0.72, rng, subdiv=0)
            self.collide_cylinder("tree", f"tree {k}", x, y, 0.3, 3.0)
        for k, (x, y, yaw) in enumerate(town.lamps):
            base = np.array([x, y, 0.0])
            self.meshes["metal"].cylinder(base, 0.12, 6.5, 6, top_radius=0.08)
            d = np.array([np.cos(yaw), np.sin(yaw), 0.0])
            self.meshes["metal"].box(
                base + d * 0.9 + np.array([0, 0, 6.4]), np.array([0.9, 0.05, 0.05]), yaw
            )
            head = base + d * LAMP_REACH_M + np.array([0, 0, LAMP_HEIGHT_M + 0.1])
            self.meshes["metal"].box(head, np.array([0.3, 0.15, 0.1]), yaw)
            # its diffuser, facing down just under the head
            side = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
            self.meshes["lamp_glow"].quad(
                head - d * 0.28 + side * 0.13 - np.array([0, 0, 0.11]), d, -side, 0.56, 0.26
            )
            self.collide_cylinder("pole", f"lamp {k}", x, y, 0.15, 3.0)
        for k, (x, y, yaw, kind) in enumerate(town.signs):
            base = np.array([x, y, 0.0])
            self.meshes["metal"].cylinder(base, 0.05, 2.9, 6)
            f = np.array([np.cos(yaw), np.sin(yaw), 0.0])
            r = np.array([np.sin(yaw), -np.cos(yaw), 0.0])  # right of the sign's face direction
            cu, cv = int(kind) % 4, int(kind) // 4
            o = base + f * 0.06 - r * 0.35 + np.array([0, 0, 2.2])
            self.meshes["signs"].quad(
                o, r, np.array([0, 0, 1.0]), 0.7, 0.7, (cu / 4, (cv + 1) / 2), (1 / 2.8, -1 / 1.4)
            )
            self.meshes["metal"].quad(o + r * 0.7 - f * 0.02, -r, np.array([0, 0, 1.0]), 0.7, 0.7)
            self.collide_cylinder("pole", f"sign {k}", x, y, 0.1, 3.0)
        for k, (x, y) in enumerate(town.bollards):
            self.meshes["metal"].cylinder(np.array([x, y, 0.0]), 0.1, 0.9, 6)
            self.collide_cylinder("pole", f"bollard {k}", x, y, 0.12, 0.9)
        for k, (x, y, yaw, color) in enumerate(town.parked_cars):
            self.car_mesh(f"car{int(color)}", np.array([x, y]), yaw)
            self.collide_box(
                "parked_car",
                f"parked car {k}",
                np.array([x, y, 0.75]),
                np.array([*CAR_HALF_M, 0.75]),
                yaw,
            )

    def car_mesh(self, material: str, xy: Array, yaw: float) -> None:
        hx, hy = CAR_HALF_M
        self.meshes[material].box(np.array([xy[0], xy[1], 0.65]), np.array([hx, hy, 0.35]), yaw)
        c, s = np.cos(yaw), np.sin(yaw)
        cab = np.array([xy[0] - 0.3 * c, xy[1] - 0.3 * s, 1.25])
        self.meshes["glass"].box(cab, np.array([hx * 0.55, hy * 0.92, 0.26]), yaw)

    # -- bodies ---------------------------------------------------------------------------------
    def bodies(self) -> None:
        hx, hy = CAR_HALF_M
        ego = self.spec.worldbody.add_body(name="ego")
        ego.add_freejoint(name="ego")
        ego.add_geom(
            name="ego_body",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=[0, 0, 0.95],
            size=[hx, hy, 0.65],
            group=GROUP_EGO,
            contype=1,
            conaffinity=0,
            rgba=[0.8, 0.1, 0.1, 1],
        )
        # drives onto a sidewalk far enough: this low, narrow box reaches the slab
        ego.add_geom(
            name="ego_curb",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=[0, 0, 0.08],
            size=[hx * 0.6, 0.35, 0.05],
            group=GROUP_EGO,
            contype=1,
            conaffinity=0,
            rgba=[0.2, 0.2, 0.2, 1],
        )
        for side in (1, -1):
            ego.add_light(
                name=f"headlight_{'left' if side > 0 else 'right'}",
                type=mujoco.mjtLightType.mjLIGHT_SPOT,
                pos=[hx, side * 0.7, 0.75],
                dir=[1.0, -0.25 * side - 0.1, -0.12],
                cutoff=50.0,
                exponent=2.0,
                attenuation=[1.0, 0.0, 0.004],
                diffuse=[1.0, 0.97, 0.88],
                ambient=[0, 0, 0],
                specular=[0.3, 0.3, 0.3],
                castshadow=False,
                active=False,
            )
        for k in range(self.options.max_cars):
            car = self.spec.worldbody.add_body(name=f"traffic_car{k}", pos=[0, 0, -50])
            car.add_freejoint(name=f"traffic_car{k}")
            color = CAR_COLORS[k % len(CAR_COLORS)]
            car.add_geom(
                name=f"car_body{k}",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                pos=[0, 0, 0.65],
                size=[hx, hy, 0.35],
                group=GROUP_TRAFFIC,
                contype=0,
                conaffinity=1,
                rgba=[*color, 1],
            )
            car.add_geom(
                name=f"car_cabin{k}",
                type=mujoco.mjtGeom.mjGEOM_BOX,
                pos=[-0.3, 0, 1.25],
                size=[hx * 0.55, hy * 0.92, 0.26],
                group=GROUP_TRAFFIC,
                contype=0,
                conaffinity=1,
                rgba=[0.08, 0.1, 0.12, 1],
            )
        for k in range(self.options.max_pedestrians):
            ped = self.spec.worldbody.add_body(name=f"pedestrian{k}", pos=[0, 0, -50])
            ped.add_freejoint(name=f"pedestrian{k}")
            shirt = self.rng.uniform(0.1, 0.9, 3)
            ped.add_geom(
                name=f"ped_body{k}",
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                pos=[0, 0, 0.85],
                size=[0.22, 0.55, 0],
                group=GROUP_TRAFFIC,
                contype=0,
                conaffinity=1,
                rgba=[*shirt, 1],
            )
            ped.add_geom(
                name=f"ped_head{k}",
                type=mujoco.mjtGeom.mjGEOM_SPHERE,
                pos=[0, 0, 1.65],
                size=[0.13, 0, 0],
                group=GROUP_TRAFFIC,
                contype=0,
                conaffinity=1,
                rgba=[0.85, 0.67, 0.55, 1],
            )

    def build(self) -> TownScene:
        spec = self.spec
        spec.modelname = self.town.name
        vis = spec.visual
        vis.global_.offwidth = vis.global_.offheight = self.options.max_image_size
        vis.headlight.active = 0
        vis.quality.shadowsize = 1024  # measured: the same images as 4096 here, 40 % less time
        self.make_assets()
        self.ground()
        self.roads()
        self.platforms()
        self.buildings()
        self.props()
        self.edge()
        season_geoms = self._mesh_geoms()
        spec.worldbody.add_light(
            name="sun",
            type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
            dir=[0.3, 0.4, -0.85],
            diffuse=[0.8, 0.8, 0.8],
            ambient=[0.3, 0.3, 0.3],
            specular=[0.2, 0.2, 0.2],
            castshadow=False,
        )
        self.bodies()
        return self._scene(spec.compile(), season_geoms)

    def _mesh_geoms(self) -> dict[str, list[str]]:
        """One visual mesh geom per material; returns the geoms whose material changes with the
        season, by material."""
        season_geoms: dict[str, list[str]] = defaultdict(list)
        for name, mb in self.meshes.items():
            if not mb:
                continue
            v, uv, f = mb.arrays()
            mesh = self.spec.add_mesh(name=f"mesh_{name}")
            mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
            mesh.uservert = v.ravel().tolist()
            mesh.usertexcoord = uv.ravel().tolist()
            mesh.userface = f.ravel().tolist()
            group = {"leaves_full": GROUP_FOLIAGE_FULL, "leaves_sparse": GROUP_FOLIAGE_SPARSE}.get(
                name, GROUP_STATIC
            )
            self.spec.worldbody.add_geom(
                name=f"vis_{name}",
                type=mujoco.mjtGeom.mjGEOM_MESH,
                meshname=f"mesh_{name}",
                material=name,
                contype=0,
                conaffinity=0,
                group=group,
            )
            if name in (*SEASON_MATERIALS, "intersection"):
                season_geoms[name].append(f"vis_{name}")
        return season_geoms

    def _scene(self, model: mujoco.MjModel, season_geoms: dict[str, list[str]]) -> TownScene:
        """The compiled model with its lookup tables; traffic parked out of sight, the ego car at
        the route's start."""
        geom_info = {model.geom(f"col{k}").id: info for k, info in enumerate(self.collision)}
        for k in range(self.options.max_cars):
            for g in (f"car_body{k}", f"car_cabin{k}"):
                geom_info[model.geom(g).id] = ("car", f"traffic car {k}")
        for k in range(self.options.max_pedestrians):
            for g in (f"ped_body{k}", f"ped_head{k}"):
                geom_info[model.geom(g).id] = ("pedestrian", f"pedestrian {k}")

        def qadr(joint: str) -> int:
            return int(model.jnt_qposadr[model.joint(joint).id])

        scene = TownScene(
            town=self.town,
            options=self.options,
            model=model,
            data=mujoco.MjData(model),
            geom_info=geom_info,
            season_geoms={k: [model.geom(n).id for n in v] for k, v in season_geoms.items()},
            material_ids={name: model.material(name).id for name in self.materials},
            sky_texture_id=model.texture("sky").id,
            sun_light_id=model.light("sun").id,
            headlight_ids=(model.light("headlight_left").id, model.light("headlight_right").id),
            night_geom_ids=tuple(model.geom(f"vis_{name}").id for name in NIGHT_MESHES),
            window_texture_id=model.texture("windows_lit").id,
            ego_qpos_adr=qadr("ego"),
            car_qpos_adr=tuple(qadr(f"traffic_car{k}") for k in range(self.options.max_cars)),
            pedestrian_qpos_adr=tuple(
                qadr(f"pedestrian{k}") for k in range(self.options.max_pedestrians)
            ),
        )
        scene.base_rgba = {n: model.mat_rgba[i].copy() for n, i in scene.material_ids.items()}
        for k in range(self.options.max_cars):
            scene.set_free_pose(scene.car_qpos_adr[k], 0.0, 0.0, 0.0, -50.0)
        for k in range(self.options.max_pedestrians):
            scene.set_free_pose(scene.pedestrian_qpos_adr[k], 0.0, 0.0, 0.0, -50.0)
        route = self.town.route
        x_m, y_m = route.waypoints_xy[0]
        scene.set_free_pose(scene.ego_qpos_adr, float(x_m), float(y_m), float(route.yaw_rad[0]))
        scene.forward()
        return scene


def _branch(start: Array, tip: Array, radius: float) -> tuple[Array, Array, NDArray[np.int64]]:
    """A thin 4-sided prism from ``start`` to ``tip``."""
    d = tip - start
    side = np.cross(d, [0.0, 0.0, 1.0])
    side = side / (np.linalg.norm(side) + 1e-9) * radius
    up = np.cross(side, d)
    up = up / (np.linalg.norm(up) + 1e-9) * radius
    ring = np.array([side, up, -side, -up])
    verts = np.concatenate([start + ring, tip + ring * 0.4])
    faces = []
    for k in range(4):
        a, b = k, (k + 1) % 4
        faces += [[a, b, b + 4], [a, b + 4, a + 4]]
    uv = np.concatenate([np.zeros((4, 2)), np.ones((4, 2))])
    return verts, uv, np.array(faces, dtype=np.int64)


WALL_VARIANT_GAP = 3  # a cell's variant differs from the 3 before it in its row and the one below


def wall_variants(
    floors: int, bays: int, count: int, rng: np.random.Generator
) -> NDArray[np.int64]:
    """The atlas variant of every cell of a wall, (floors, bays) from the bottom left: each
    differs from the ``WALL_VARIANT_GAP`` cells before it in its row and from the cell below
    (where ``count`` leaves a choice). Drawn freely, 1 in 12 neighbours were the same cell, whose
    grain and windows matched one bay over: in town01 an answer 3.78 m off (one bay) with 96
    inliers against the truth's 81 crashed the car at the same turn in every repetition."""
    cells = np.zeros((floors, bays), np.int64)
    for f in range(floors):
        for j in range(bays):
            taken = set(cells[f, max(0, j - WALL_VARIANT_GAP) : j].tolist())
            if f:
                taken.add(int(cells[f - 1, j]))
            free = [v for v in range(count) if v not in taken] or list(range(count))
            cells[f, j] = free[int(rng.integers(0, len(free)))]
    return cells


def shop_plan(town: Town) -> dict[int, list[int]]:
    """The shopfront tile of every shop bay, per building index: each bay takes a tile not yet
    used, then the tile whose nearest use is farthest away (ties drawn from the town's seed).
    Per-building random draws put the same shop twice on one street, 17 m off answers that
    passed the EKF's gate; a repeat hundreds of metres away is gated."""
    count = town.spec.buildings.shop_styles
    rng = np.random.default_rng((town.spec.seed, 2))
    placed_xy: list[Array] = []  # every bay planned so far (2,), and its tile
    placed_tile: list[int] = []
    plan: dict[int, list[int]] = {}
    for k, b in enumerate(town.buildings):
        if not b.shop:
            continue
        plan[k] = []
        for centre in shop_bays(b):
            gap = np.full(count, np.inf)  # from this bay to each tile's nearest use
            if placed_xy:
                dist = np.linalg.norm(np.array(placed_xy) - centre, axis=1)
                np.minimum.at(gap, placed_tile, dist)
            best = np.flatnonzero(gap == gap.max())
            shop = int(best[rng.integers(0, len(best))])
            placed_xy.append(centre)
            placed_tile.append(shop)
            plan[k].append(shop)
    return plan


def shop_bays(building: Building) -> list[Array]:
    """The centres (2,) of the shop bays along a building's front, in metres."""
    a, u, length = building_side(building.rect, "SENW".index(building.front))
    n = max(1, round(length / tex.SHOP_WIDTH_M))
    return [(a + u * (j + 0.5) * length / n)[:2] for j in range(n)]


def building_side(rect: tuple[float, float, float, float], side: int) -> tuple[Array, Array, float]:
    """Side ``side`` (0..3: S, E, N, W) of a building's footprint, walked counter-clockwise:
    its first corner (3,) at ground level, its direction (3,) and its length in metres."""
    x0, y0, x1, y1 = rect
    corners = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
    a = np.array([*corners[side], 0.0])
    c = np.array([*corners[(side + 1) % 4], 0.0])
    length = float(np.linalg.norm(c - a))
    return a, (c - a) / length, length


def _slab_boxes(
    rect: tuple[float, float, float, float], radius: float
) -> list[tuple[float, float, float, float]]:
    """Boxes inside a rounded rectangle that cover it up to a few centimetres at the corners."""
    x0, y0, x1, y1 = rect
    if radius <= 0:
        return [rect]
    r = radius
    boxes = [(x0 + r, y0, x1 - r, y1), (x0, y0 + r, x0 + r, y1 - r), (x1 - r, y0 + r, x1, y1 - r)]
    # each corner quarter-disc as strips whose outer corners stay inside the circle
    for k in range(3):
        a, b = k * r / 3.5, (k + 1) * r / 3.5  # distance from the corner circle's centre along x
        half = float(np.sqrt(r * r - b * b))  # strip height that stays inside the circle
        for cx, cy, sx, sy in (
            (x0 + r, y0 + r, -1, -1),
            (x1 - r, y0 + r, 1, -1),
            (x1 - r, y1 - r, 1, 1),
            (x0 + r, y1 - r, -1, 1),
        ):
            xa, xb = sorted((cx + sx * a, cx + sx * b))
            ya, yb = sorted((cy, cy + sy * half))
            boxes.append((xa, ya, xb, yb))
    return boxes


def build_scene(town: Town, options: SceneOptions | None = None) -> TownScene:
    """Compile ``town`` into a MuJoCo model (deterministic in the town's seed)."""
    return _SceneBuilder(town, options or SceneOptions()).build()
