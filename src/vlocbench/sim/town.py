"""Procedural grid towns: spec (YAML), deterministic generation, and the generated layout.

A town is a grid of roads (``block_widths_m`` x ``block_depths_m`` between road centre lines) with
raised sidewalk platforms (curbs, rounded corners), rows of buildings along every road-facing lot
edge, towers in some city blocks, parks, an optional beach side, and street furniture (trees, lamps,
traffic signs, bollards, parked cars). Generation is a pure function of the spec and its seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Literal

import networkx as nx
import numpy as np

from vlocbench.config import from_dict, load_yaml, require
from vlocbench.errors import UnknownNameError
from vlocbench.interfaces import Array
from vlocbench.sim.roads import RoadLayout, Route, build_lane_graph, build_route

ROUTE_LENGTH_TOLERANCE = 0.1  # of RouteSpec.target_length_m
Rect = tuple[float, float, float, float]  # x0, y0, x1, y1 (metres, x0 < x1, y0 < y1)
Side = Literal["none", "south", "north", "west", "east"]


@dataclass(frozen=True)
class RoadSpec:
    lane_width_m: float = 4.0
    lanes_per_direction: int = 1  # the route keeps to the lane next to the centre line
    sidewalk_width_m: float = 3.0
    curb_height_m: float = 0.15
    corner_radius_m: float = 6.0

    def __post_init__(self) -> None:
        require(2.5 <= self.lane_width_m <= 6.0, "road.lane_width_m", "must be in [2.5, 6] m")
        require(1 <= self.lanes_per_direction <= 3, "road.lanes_per_direction", "must be 1, 2 or 3")
        require(1.0 <= self.sidewalk_width_m <= 10.0, "road.sidewalk_width_m", "must be in [1, 10]")
        require(0.0 < self.curb_height_m <= 0.4, "road.curb_height_m", "must be in (0, 0.4] m")
        require(3.0 <= self.corner_radius_m <= 20.0, "road.corner_radius_m", "must be in [3, 20]")


@dataclass(frozen=True)
class BuildingSpec:
    floors: tuple[int, int] = (2, 4)
    floor_height_m: float = 3.2
    frontage_m: tuple[float, float] = (9.0, 20.0)
    depth_m: tuple[float, float] = (9.0, 15.0)
    gap_probability: float = 0.15
    tower_block_fraction: float = 0.0
    tower_floors: tuple[int, int] = (15, 40)
    facade_styles: int = 12  # distinct facade textures; few styles = repetitive, aliasing facades
    shop_probability: float = 0.6
    # distinct shopfront tiles; few make streets look alike to a localizer (town10 keeps 6)
    shop_styles: int = 6

    def __post_init__(self) -> None:
        for name in ("floors", "frontage_m", "depth_m", "tower_floors"):
            lo, hi = getattr(self, name)
            require(0 < lo <= hi, f"buildings.{name}", "needs 0 < min <= max")
        require(
            2.5 <= self.floor_height_m <= 6.0, "buildings.floor_height_m", "must be in [2.5, 6]"
        )
        require(0 <= self.gap_probability < 1, "buildings.gap_probability", "must be in [0, 1)")
        require(
            0 <= self.tower_block_fraction <= 1,
            "buildings.tower_block_fraction",
            "must be in [0, 1]",
        )
        require(1 <= self.facade_styles <= 32, "buildings.facade_styles", "must be in [1, 32]")
        require(0 <= self.shop_probability <= 1, "buildings.shop_probability", "must be in [0, 1]")
        require(1 <= self.shop_styles <= 64, "buildings.shop_styles", "must be in [1, 64]")


@dataclass(frozen=True)
class PropSpec:
    tree_spacing_m: float = 14.0
    lamp_spacing_m: float = 28.0
    bollard_spacing_m: float = 0.0  # 0: none
    parked_car_probability: float = 0.6  # per gap between buildings wide enough for a car
    park_tree_spacing_m: float = 9.0

    def __post_init__(self) -> None:
        for name in ("tree_spacing_m", "lamp_spacing_m", "bollard_spacing_m"):
            value = getattr(self, name)
            require(value == 0 or value >= 3, f"props.{name}", "must be 0 (none) or >= 3 m")
        require(
            0 <= self.parked_car_probability <= 1,
            "props.parked_car_probability",
            "must be in [0, 1]",
        )
        require(self.park_tree_spacing_m >= 3, "props.park_tree_spacing_m", "must be >= 3 m")


@dataclass(frozen=True)
class RouteSpec:
    nodes: tuple[tuple[int, int], ...]
    start_offset_m: float = 20.0
    end_offset_m: float = 20.0
    # the length the route is meant to have (the paper's routes); a spec whose nodes and offsets
    # give a route more than ROUTE_LENGTH_TOLERANCE off it is refused
    target_length_m: float | None = None


@dataclass(frozen=True)
class TownSpec:
    """Everything that defines a town. Loaded from YAML (see ``sim/towns/*.yaml``)."""

    name: str
    block_widths_m: tuple[float, ...]
    block_depths_m: tuple[float, ...]
    route: RouteSpec
    seed: int = 0
    style: Literal["town", "city"] = "town"
    border_m: float = 40.0
    parks: tuple[tuple[int, int], ...] = ()
    beach_side: Side = "none"
    road: RoadSpec = field(default_factory=RoadSpec)
    buildings: BuildingSpec = field(default_factory=BuildingSpec)
    props: PropSpec = field(default_factory=PropSpec)

    def __post_init__(self) -> None:
        require(bool(self.name), "name", "must not be empty")
        require(len(self.block_widths_m) >= 1, "block_widths_m", "needs at least one block")
        require(len(self.block_depths_m) >= 1, "block_depths_m", "needs at least one block")
        half_road_m = self.road.lanes_per_direction * self.road.lane_width_m
        min_block = 2 * (half_road_m + self.road.corner_radius_m) + 10
        for name in ("block_widths_m", "block_depths_m"):
            for k, w in enumerate(getattr(self, name)):
                require(w >= min_block, f"{name}[{k}]", f"must be >= {min_block:g} m, got {w:g}")
        require(self.border_m >= 15, "border_m", "must be >= 15 m")
        for k, (i, j) in enumerate(self.parks):
            require(
                0 <= i < len(self.block_widths_m) and 0 <= j < len(self.block_depths_m),
                f"parks[{k}]",
                f"block ({i}, {j}) is outside the {len(self.block_widths_m)}x"
                f"{len(self.block_depths_m)} grid",
            )

    @classmethod
    def from_yaml(cls, path: str | Path) -> TownSpec:
        return from_dict(cls, load_yaml(path))


def road_layout(
    block_widths_m: tuple[float, ...], block_depths_m: tuple[float, ...], road: RoadSpec
) -> RoadLayout:
    """The road grid of blocks this wide and deep (m), its first centre line at 0."""
    return RoadLayout(
        np.concatenate([[0.0], np.cumsum(block_widths_m)]),
        np.concatenate([[0.0], np.cumsum(block_depths_m)]),
        road.lane_width_m,
        road.corner_radius_m,
        road.lanes_per_direction,
    )


def builtin_town_names() -> list[str]:
    folder = resources.files("vlocbench.sim") / "towns"
    return sorted(
        p.name.removesuffix(".yaml") for p in folder.iterdir() if p.name.endswith(".yaml")
    )


def load_town_spec(name_or_path: str | Path) -> TownSpec:
    """A built-in town by name (``town01``, ``town10``), a generated town by its name
    (:mod:`vlocbench.sim.generation`) or a user's town spec YAML file."""
    from vlocbench.sim import generation  # it builds on this module

    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        return TownSpec.from_yaml(path)
    name = str(name_or_path)
    if generation.is_generated_name(name):
        return generation.generated_spec(name)
    if name not in builtin_town_names():
        raise UnknownNameError("town", name, [*builtin_town_names(), *generation.NAME_PATTERNS])
    with resources.as_file(resources.files("vlocbench.sim") / "towns" / f"{name}.yaml") as p:
        return TownSpec.from_yaml(p)


@dataclass(frozen=True)
class Building:
    """An axis-aligned building. ``front`` is the side facing its road: N, S, E or W."""

    rect: Rect
    height_m: float
    floors: int
    facade: int  # facade style index
    tint: int  # colour variant of the style
    shop: bool  # shops on the ground floor of its front (the scene chooses their tiles)
    front: str
    tower: bool = False


@dataclass(frozen=True)
class Platform:
    """A raised sidewalk platform; ``corner_radius_m`` > 0 rounds all four corners."""

    rect: Rect
    corner_radius_m: float


@dataclass(frozen=True)
class Town:
    """A generated town. Arrays are (N, k) with columns named in each field's comment."""

    spec: TownSpec
    layout: RoadLayout
    platforms: tuple[Platform, ...]
    buildings: tuple[Building, ...]
    grass: tuple[Rect, ...]
    sand: tuple[Rect, ...]
    water: tuple[Rect, ...]
    trees: Array  # x, y, trunk height m, crown radius m
    lamps: Array  # x, y, arm yaw rad (towards the road)
    signs: Array  # x, y, face yaw rad, sign kind
    bollards: Array  # x, y
    parked_cars: Array  # x, y, yaw rad, colour index
    route: Route
    extent: Rect  # bounds of everything generated

    @property
    def name(self) -> str:
        return self.spec.name

    @cached_property
    def lane_graph(self) -> nx.DiGraph:
        return build_lane_graph(self.layout)

    def sidewalk_loops(self) -> list[Array]:
        """Closed (N, 2) paths along the middle of each interior block's sidewalk (for walkers)."""
        loops = []
        inset = 0.5 * self.spec.road.sidewalk_width_m
        for p in self.platforms:
            if p.corner_radius_m <= 0:
                continue
            x0, y0, x1, y1 = p.rect
            loops.append(
                np.array(
                    [
                        [x0 + inset, y0 + inset],
                        [x1 - inset, y0 + inset],
                        [x1 - inset, y1 - inset],
                        [x0 + inset, y1 - inset],
                        [x0 + inset, y0 + inset],
                    ]
                )
            )
        return loops


class _Builder:
    def __init__(self, spec: TownSpec) -> None:
        self.spec = spec
        self.rng = np.random.default_rng(spec.seed)
        self.layout = road_layout(spec.block_widths_m, spec.block_depths_m, spec.road)
        self.hw = self.layout.half_width_m
        self.sw = spec.road.sidewalk_width_m
        self.platforms: list[Platform] = []
        self.buildings: list[Building] = []
        self.grass: list[Rect] = []
        self.sand: list[Rect] = []
        self.water: list[Rect] = []
        self.trees: list[tuple[float, float, float, float]] = []
        self.lamps: list[tuple[float, float, float]] = []
        self.signs: list[tuple[float, float, float, float]] = []
        self.bollards: list[tuple[float, float]] = []
        self.parked: list[tuple[float, float, float, float]] = []

    # -- streets ------------------------------------------------------------------------------
    def curb_props(self, a: Array, b: Array, toward_road: Array, margin_m: float) -> None:
        """Trees, lamps and bollards along the curb edge a->b (clear of the corners)."""
        props = self.spec.props
        direction = (b - a) / np.linalg.norm(b - a)
        length = float(np.linalg.norm(b - a))
        usable = length - 2 * margin_m
        if usable <= 2:
            return
        yaw_road = float(np.arctan2(toward_road[1], toward_road[0]))

        def positions(spacing: float, phase: float) -> Array:
            if spacing <= 0:
                return np.empty(0)
            s = np.arange(margin_m + phase * spacing, length - margin_m, spacing)
            return s + self.rng.uniform(-0.15, 0.15, len(s)) * spacing

        for s in positions(props.tree_spacing_m, 0.5):
            p = a + direction * s - toward_road * 0.9
            self.trees.append((p[0], p[1], *self._tree_size()))
        for s in positions(props.lamp_spacing_m, 0.25):
            p = a + direction * s - toward_road * 0.5
            self.lamps.append((p[0], p[1], yaw_road))
        for s in positions(props.bollard_spacing_m, 0.1):
            p = a + direction * s - toward_road * 0.35
            self.bollards.append((p[0], p[1]))

    def _tree_size(self) -> tuple[float, float]:
        return float(self.rng.uniform(2.2, 3.5)), float(self.rng.uniform(1.6, 2.8))

    def corner_signs(self, rect: Rect) -> None:
        """A traffic sign on some rounded corners of an interior block, facing the traffic."""
        x0, y0, x1, y1 = rect
        r = self.spec.road.corner_radius_m
        for cx, cy, sx, sy in ((x0, y0, 1, 1), (x1, y0, -1, 1), (x1, y1, -1, -1), (x0, y1, 1, -1)):
            if self.rng.random() < 0.55:
                # on the corner arc's midpoint, 0.6 m in from the curb
                c = np.array([cx + sx * r, cy + sy * r])
                p = c - np.array([sx, sy]) / np.sqrt(2) * (r - 0.6)
                yaw = float(np.arctan2(-sy, -sx)) + self.rng.choice([-0.6, 0.6])
                self.signs.append((p[0], p[1], yaw, float(self.rng.integers(0, 8))))

    # -- buildings ----------------------------------------------------------------------------
    def building_row(self, a: Array, b: Array, inward: Array, depth_max: float, front: str) -> None:
        """Buildings along the lot edge a->b, extending ``inward`` by up to ``depth_max``."""
        bs = self.spec.buildings
        direction = (b - a) / np.linalg.norm(b - a)
        length = float(np.linalg.norm(b - a))
        s = 0.0
        while length - s > 3.0:
            width = float(self.rng.uniform(*bs.frontage_m))
            if length - s - width < bs.frontage_m[0]:
                width = length - s
            if self.rng.random() < bs.gap_probability and width > 8 and s > 0:
                gap = float(self.rng.uniform(4.0, 7.0))
                self.gap(a + direction * (s + gap / 2), direction, inward, gap)
                s += gap
                continue
            depth = min(depth_max, float(self.rng.uniform(*bs.depth_m)))
            p0 = a + direction * s
            p1 = a + direction * (s + width) + inward * depth
            rect = (min(p0[0], p1[0]), min(p0[1], p1[1]), max(p0[0], p1[0]), max(p0[1], p1[1]))
            self.add_building(rect, front, tower=False)
            s += width

    def gap(self, center: Array, direction: Array, inward: Array, width: float) -> None:
        if width >= 4.0 and self.rng.random() < self.spec.props.parked_car_probability:
            p = center + inward * 4.0
            yaw = float(np.arctan2(inward[1], inward[0]))
            self.parked.append((p[0], p[1], yaw, float(self.rng.integers(0, 8))))
        else:
            p = center + inward * 2.0
            self.trees.append((p[0], p[1], *self._tree_size()))

    def add_building(self, rect: Rect, front: str, tower: bool) -> None:
        bs = self.spec.buildings
        lo, hi = bs.tower_floors if tower else bs.floors
        floors = int(self.rng.integers(lo, hi + 1))
        height = floors * bs.floor_height_m + 0.6  # parapet
        n_styles = bs.facade_styles
        facade = int(self.rng.integers(0, n_styles))
        shop = bool(self.rng.random() < bs.shop_probability)
        if shop:
            # scene 6 took its tile from this draw; the scene plans the tiles now (apart, across
            # the town), and the draw stays so that every later draw of a town stays where it was
            self.rng.integers(0, bs.shop_styles)
        self.buildings.append(
            Building(rect, height, floors, facade, int(self.rng.integers(0, 3)), shop, front, tower)
        )

    def lot(self, rect: Rect, road_sides: str) -> None:
        """Buildings along the road-facing sides (subset of 'SNWE') of a lot."""
        x0, y0, x1, y1 = rect
        dmax = 0.5 * min(x1 - x0, y1 - y0) - 1.0
        dmax_x = 0.5 * (y1 - y0) - 1 if "S" in road_sides and "N" in road_sides else y1 - y0 - 2
        dmax_y = 0.5 * (x1 - x0) - 1 if "W" in road_sides and "E" in road_sides else x1 - x0 - 2
        bs = self.spec.buildings
        d_s = d_n = 0.0
        if "S" in road_sides:
            d_s = min(bs.depth_m[1], dmax_x)
            self.building_row(np.array([x0, y0]), np.array([x1, y0]), np.array([0, 1.0]), d_s, "S")
        if "N" in road_sides:
            d_n = min(bs.depth_m[1], dmax_x)
            self.building_row(np.array([x1, y1]), np.array([x0, y1]), np.array([0, -1.0]), d_n, "N")
        if "W" in road_sides:
            a, b = np.array([x0, y1 - d_n]), np.array([x0, y0 + d_s])
            if b[1] - a[1] < -4:
                self.building_row(a, b, np.array([1.0, 0]), min(bs.depth_m[1], dmax_y, dmax), "W")
        if "E" in road_sides:
            a, b = np.array([x1, y0 + d_s]), np.array([x1, y1 - d_n])
            if b[1] - a[1] > 4:
                self.building_row(a, b, np.array([-1.0, 0]), min(bs.depth_m[1], dmax_y, dmax), "E")

    def towers(self, rect: Rect) -> None:
        """One to four towers on a city block with a plaza between them."""
        x0, y0, x1, y1 = rect
        w, d = x1 - x0, y1 - y0
        nx_, ny_ = (2 if w > 50 else 1), (2 if d > 50 else 1)
        cw, cd = w / nx_, d / ny_
        for a in range(nx_):
            for b in range(ny_):
                fw = cw * float(self.rng.uniform(0.6, 0.85))
                fd = cd * float(self.rng.uniform(0.6, 0.85))
                # towers stand at the lot's outer edges so that their facades face the streets
                bx = x0 + a * cw + (0 if a == 0 else cw - fw)
                by = y0 + b * cd + (0 if b == 0 else cd - fd)
                front = "S" if b == 0 else "N"
                self.add_building((bx, by, bx + fw, by + fd), front, tower=True)

    def park(self, rect: Rect) -> None:
        x0, y0, x1, y1 = rect
        self.grass.append(rect)
        spacing = self.spec.props.park_tree_spacing_m
        for x in np.arange(x0 + spacing / 2, x1 - 1, spacing):
            for y in np.arange(y0 + spacing / 2, y1 - 1, spacing):
                if self.rng.random() < 0.7:
                    jx, jy = self.rng.uniform(-0.3, 0.3, 2) * spacing
                    self.trees.append((x + jx, y + jy, *self._tree_size()))

    # -- whole town -----------------------------------------------------------------------------
    def build(self) -> Town:
        spec = self.spec
        xs, ys = self.layout.xs, self.layout.ys
        blocks = [(i, j) for i in range(len(xs) - 1) for j in range(len(ys) - 1)]
        tower_blocks = self._tower_blocks(blocks)
        for block in blocks:
            self.block(block, block in tower_blocks)
        self.border()
        corners = np.array([p.rect for p in self.platforms] + self.sand + self.water)
        extent = (
            float(corners[:, 0].min()),
            float(corners[:, 1].min()),
            float(corners[:, 2].max()),
            float(corners[:, 3].max()),
        )
        return Town(
            spec=spec,
            layout=self.layout,
            platforms=tuple(self.platforms),
            buildings=tuple(self.buildings),
            grass=tuple(self.grass),
            sand=tuple(self.sand),
            water=tuple(self.water),
            trees=_arr(self.trees, 4),
            lamps=_arr(self.lamps, 3),
            signs=_arr(self.signs, 4),
            bollards=_arr(self.bollards, 2),
            parked_cars=_arr(self.parked, 4),
            route=self.route(),
            extent=extent,
        )

    def _tower_blocks(self, blocks: list[tuple[int, int]]) -> set[tuple[int, int]]:
        """The city blocks (not parks) that get towers: ``tower_block_fraction`` of all."""
        fraction = self.spec.buildings.tower_block_fraction
        if fraction <= 0:
            return set()
        candidates = [b for b in blocks if b not in set(self.spec.parks)]
        picks = self.rng.permutation(len(candidates))[: round(fraction * len(blocks))]
        return {candidates[k] for k in picks}

    def block(self, block: tuple[int, int], towers: bool) -> None:
        """One city block: its raised sidewalk platform, a park, towers or a row of buildings on
        every side, and the props along its curbs."""
        (i, j), xs, ys = block, self.layout.xs, self.layout.ys
        hw, sw, r = self.hw, self.sw, self.spec.road.corner_radius_m
        curb = (xs[i] + hw, ys[j] + hw, xs[i + 1] - hw, ys[j + 1] - hw)
        self.platforms.append(Platform(curb, r))
        lot = (curb[0] + sw, curb[1] + sw, curb[2] - sw, curb[3] - sw)
        if block in set(self.spec.parks):
            self.park(lot)
        elif towers:
            self.towers(lot)
        else:
            self.lot(lot, "SNWE")
        cx0, cy0, cx1, cy1 = curb
        for a, b, n in (
            ((cx0, cy0), (cx1, cy0), (0, -1)),
            ((cx1, cy0), (cx1, cy1), (1, 0)),
            ((cx1, cy1), (cx0, cy1), (0, 1)),
            ((cx0, cy1), (cx0, cy0), (-1, 0)),
        ):
            self.curb_props(np.array(a), np.array(b), np.array(n, float), r + 1.0)
        self.corner_signs(curb)

    def route(self) -> Route:
        """The test route, checked against its target length."""
        spec = self.spec
        route = build_route(
            self.layout, spec.route.nodes, spec.route.start_offset_m, spec.route.end_offset_m
        )
        target = spec.route.target_length_m
        require(
            target is None or abs(route.length_m - target) <= ROUTE_LENGTH_TOLERANCE * target,
            "route.target_length_m",
            f"the route's nodes and offsets give {route.length_m:.0f} m, more than "
            f"{ROUTE_LENGTH_TOLERANCE:.0%} off {target} m",
        )
        return route

    def border(self) -> None:
        """Strips outside the ring road: a row of buildings facing it, or the beach."""
        xs, ys = self.layout.xs, self.layout.ys
        hw, sw, b = self.hw, self.sw, self.spec.border_m
        strips = {
            "south": ((xs[0] - b, ys[0] - b, xs[-1] + b, ys[0] - hw), "N"),
            "north": ((xs[0] - b, ys[-1] + hw, xs[-1] + b, ys[-1] + b), "S"),
            "west": ((xs[0] - b, ys[0] - hw, xs[0] - hw, ys[-1] + hw), "E"),
            "east": ((xs[-1] + hw, ys[0] - hw, xs[-1] + b, ys[-1] + hw), "W"),
        }
        for side, (rect, road_side) in strips.items():
            x0, y0, x1, y1 = rect
            curb_edge = {
                "N": ((x1, y1), (x0, y1), (0, 1)),
                "S": ((x0, y0), (x1, y0), (0, -1)),
                "E": ((x1, y0), (x1, y1), (1, 0)),
                "W": ((x0, y1), (x0, y0), (-1, 0)),
            }[road_side]
            a, c, n = (np.array(v, dtype=np.float64) for v in curb_edge)
            if side == self.spec.beach_side:
                self.beach(rect, road_side)
                self.curb_props(a, c, n, 2.0)
                continue
            self.platforms.append(Platform(rect, 0.0))
            lot = _inset_side(rect, road_side, sw)
            # only the stretch that actually faces the ring road gets a row of buildings
            if road_side in "NS":
                lot = (xs[0] - hw - sw, lot[1], xs[-1] + hw + sw, lot[3])
            self.lot(lot, road_side)
            self.curb_props(a, c, n, 2.0)

    def beach(self, rect: Rect, road_side: str) -> None:
        """A promenade sidewalk, then sand, then open water (no buildings: few features)."""
        sw = self.sw
        promenade = _keep_side(rect, road_side, sw)
        self.platforms.append(Platform(promenade, 0.0))
        rest = _inset_side(rect, road_side, sw)
        sand = _grow(rest, _side_name(_opposite(road_side)), 25.0)
        self.sand.append(sand)
        self.water.append(
            _grow(
                _keep_side(sand, _opposite(road_side), 1.0), _side_name(_opposite(road_side)), 120.0
            )
        )


def _arr(rows: list, cols: int) -> Array:
    return np.array(rows, dtype=np.float64).reshape(-1, cols)


def _opposite(side: str) -> str:
    return {"N": "S", "S": "N", "E": "W", "W": "E"}[side]


def _side_name(side: str) -> Side:
    return {"N": "north", "S": "south", "E": "east", "W": "west"}[side]  # type: ignore[return-value]


def _inset_side(rect: Rect, side: str, d: float) -> Rect:
    """Shrink ``rect`` by ``d`` from its ``side`` (N, S, E or W)."""
    x0, y0, x1, y1 = rect
    return {
        "N": (x0, y0, x1, y1 - d),
        "S": (x0, y0 + d, x1, y1),
        "E": (x0, y0, x1 - d, y1),
        "W": (x0 + d, y0, x1, y1),
    }[side]


def _keep_side(rect: Rect, side: str, d: float) -> Rect:
    """The strip of depth ``d`` along ``side`` of ``rect``."""
    x0, y0, x1, y1 = rect
    return {
        "N": (x0, y1 - d, x1, y1),
        "S": (x0, y0, x1, y0 + d),
        "E": (x1 - d, y0, x1, y1),
        "W": (x0, y0, x0 + d, y1),
    }[side]


def _grow(rect: Rect, side: Side, d: float) -> Rect:
    x0, y0, x1, y1 = rect
    return {
        "north": (x0, y0, x1, y1 + d),
        "south": (x0, y0 - d, x1, y1),
        "east": (x0, y0, x1 + d, y1),
        "west": (x0 - d, y0, x1, y1),
        "none": rect,
    }[side]


def generate_town(spec: TownSpec) -> Town:
    """Generate the town described by ``spec`` (deterministic in ``spec.seed``)."""
    return _Builder(spec).build()
