"""Towns drawn from a distribution, so that no method can be tuned to two towns.

A *style* (``town``: low buildings and parks, like town01; ``city``: towers, avenues with two lanes
each way and a few repetitive facades, like town10) is a set of ranges around its built-in town's
spec; a set's seed and a town's index draw one spec from them, with a route of the paper's kind
(the built-in town's length and number of 90-degree turns, never driving the same street twice,
the right-facing camera always facing a row of buildings: no park, no beach on its side).
Generation is a pure function of (style, seed, index).

Generated towns are named ``gen-STYLE-SEED-INDEX``: every command that takes a town accepts the
name. A *hidden* set's towns are ``hidden-DIGEST-STYLE-INDEX``: their seed is read from
:data:`HIDDEN_SEED_ENV` (or the file :data:`HIDDEN_SEED_FILE_ENV` names) in every process that
builds them and is never written anywhere; the name carries only the seed's digest.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from vlocbench.config import from_dict, require, require_one_of
from vlocbench.errors import ConfigError
from vlocbench.sim.roads import RoadLayout, build_route
from vlocbench.sim.town import ROUTE_LENGTH_TOLERANCE, RoadSpec, TownSpec, road_layout

Style = Literal["town", "city"]
STYLES: tuple[Style, ...] = get_args(Style)
HIDDEN_SEED_ENV = "VLOCBENCH_HIDDEN_SEED"
HIDDEN_SEED_FILE_ENV = "VLOCBENCH_HIDDEN_SEED_FILE"
# a shorter seed could be found from its digest by trying every candidate
MIN_HIDDEN_SEED = 2**40
MAX_TOWNS_PER_SET = 64
# the route a style's towns get: the built-in town's (town01: 1.2 km, 5 turns; town10: 0.5 km, 6)
ROUTE_BY_STYLE: dict[str, tuple[float, int]] = {"town": (1200.0, 5), "city": (500.0, 6)}
# a drawn route is kept only this close to its target (the spec's own tolerance is wider)
ROUTE_FIT = 0.5 * ROUTE_LENGTH_TOLERANCE
MAX_DRAWS = 400  # layouts tried before a seed is given up (none needed more than 30 in tests)

GENERATED_NAME = re.compile(r"^gen-(town|city)-(\d+)-(\d+)$")
HIDDEN_NAME = re.compile(r"^hidden-([0-9a-f]{12})-(town|city)-(\d+)$")
NAME_PATTERNS = ("gen-STYLE-SEED-INDEX", "hidden-DIGEST-STYLE-INDEX")


@dataclass(frozen=True)
class TownSet:
    """``count`` towns of ``style`` drawn from ``seed`` (an experiment's ``towns: [{generate:
    ...}]``); a hidden set has no seed here: it comes from the environment."""

    count: int
    style: Style = "town"
    seed: int = 0

    def __post_init__(self) -> None:
        require(
            1 <= self.count <= MAX_TOWNS_PER_SET,
            "count",
            f"must be in [1, {MAX_TOWNS_PER_SET}], got {self.count}",
        )
        require_one_of(self.style, STYLES, "style")  # also when built directly (the CLI)
        require(self.seed >= 0, "seed", f"must be >= 0, got {self.seed}")

    def names(self) -> list[str]:
        return [f"gen-{self.style}-{self.seed}-{i}" for i in range(self.count)]

    def hidden_names(self) -> list[str]:
        digest = seed_digest(hidden_seed())
        return [f"hidden-{digest}-{self.style}-{i}" for i in range(self.count)]


def town_set_names(item: dict[str, Any], field: str) -> list[str]:
    """The town names of an experiment's ``{generate: {...}}`` or ``{hidden: {...}}`` item."""
    if len(item) != 1 or next(iter(item)) not in ("generate", "hidden"):
        raise ConfigError(field, "expected a town name, {generate: {...}} or {hidden: {...}}")
    ((kind, body),) = item.items()
    if not isinstance(body, dict):
        raise ConfigError(f"{field}.{kind}", "expected a mapping: count, style (and seed)")
    if kind == "hidden":
        require(
            "seed" not in body,
            f"{field}.hidden.seed",
            f"a hidden set's seed is never written in a file that is shared: set "
            f"{HIDDEN_SEED_ENV} or {HIDDEN_SEED_FILE_ENV}",
        )
        return from_dict(TownSet, body, f"{field}.hidden").hidden_names()
    return from_dict(TownSet, body, f"{field}.generate").names()


def is_generated_name(name: str) -> bool:
    return bool(GENERATED_NAME.match(name) or HIDDEN_NAME.match(name))


def is_hidden_name(name: str) -> bool:
    return bool(HIDDEN_NAME.match(name))


def generated_spec(name: str) -> TownSpec:
    """The spec of a generated (``gen-...``) or hidden (``hidden-...``) town by its name."""
    if match := GENERATED_NAME.match(name):
        style, seed, index = match[1], int(match[2]), int(match[3])
    elif match := HIDDEN_NAME.match(name):
        seed = hidden_seed()
        require(
            seed_digest(seed) == match[1],
            "town",
            f"{name} was drawn from a hidden seed with digest {match[1]}; the seed set in "
            f"{HIDDEN_SEED_ENV} / {HIDDEN_SEED_FILE_ENV} has digest {seed_digest(seed)}",
        )
        style, index = match[2], int(match[3])
    else:
        raise ConfigError("town", f"{name!r} is not a generated town's name ({NAME_PATTERNS})")
    return draw_town_spec(style, seed, index, name)


def seed_digest(seed: int) -> str:
    """12 hex digits that name a hidden set without revealing its seed."""
    return hashlib.sha256(f"vlocbench-hidden-set:{seed}".encode()).hexdigest()[:12]


def hidden_seed() -> int:
    """The hidden set's seed, from :data:`HIDDEN_SEED_ENV` or the file :data:`HIDDEN_SEED_FILE_ENV`
    names (a whole number >= :data:`MIN_HIDDEN_SEED`)."""
    field, text = HIDDEN_SEED_ENV, os.environ.get(HIDDEN_SEED_ENV, "").strip()
    if not text:
        path = os.environ.get(HIDDEN_SEED_FILE_ENV, "").strip()
        require(
            bool(path),
            HIDDEN_SEED_ENV,
            f"hidden towns need their set's seed: set {HIDDEN_SEED_ENV}, or "
            f"{HIDDEN_SEED_FILE_ENV} to a file that holds it",
        )
        field = HIDDEN_SEED_FILE_ENV
        try:
            text = Path(path).read_text().strip()
        except OSError as exc:
            raise ConfigError(field, f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        seed = int(text)
    except ValueError:
        raise ConfigError(field, "the hidden seed must be a whole number") from None
    require(
        seed >= MIN_HIDDEN_SEED,
        field,
        "the hidden seed must be at least 2**40, or it could be found from its digest; draw one "
        "with: python -c 'import secrets; print(secrets.randbits(64))'",
    )
    return seed


def draw_town_spec(style: str, seed: int, index: int, name: str) -> TownSpec:
    """Town ``index`` of the set (``style``, ``seed``): a spec drawn from the style's ranges, with
    a route of the style's length and turns. Deterministic in (style, seed, index)."""
    require_one_of(style, STYLES, "style")
    rng = np.random.default_rng([seed, index, STYLES.index(style)])
    for _ in range(MAX_DRAWS):
        data = _city_style(rng) if style == "city" else _town_style(rng)
        data["name"] = name
        data["seed"] = int(rng.integers(0, 2**31))
        route = _draw_route(rng, data, *ROUTE_BY_STYLE[style])
        if route is not None:
            return from_dict(TownSpec, {**data, "route": route})
    raise ConfigError("seed", f"no town of style {style} with a route found in {MAX_DRAWS} draws")


def _blocks(rng: np.random.Generator, n: tuple[int, int], size_m: tuple[int, int]) -> list[float]:
    """``n`` (min, max) blocks, each ``size_m`` (min, max) wide in steps of 5 m."""
    count = int(rng.integers(n[0], n[1] + 1))
    return [float(5 * rng.integers(size_m[0] // 5, size_m[1] // 5 + 1)) for _ in range(count)]


def _parks(rng: np.random.Generator, nx_: int, ny_: int, share: float) -> list[list[int]]:
    blocks = [[i, j] for i in range(nx_) for j in range(ny_)]
    picks = rng.permutation(len(blocks))[: round(share * len(blocks))]
    return [blocks[k] for k in sorted(picks)]


def _town_style(rng: np.random.Generator) -> dict[str, Any]:
    """Ranges around town01: 4-6 x 3-5 blocks of 70-90 m, 10-20 % parks, low buildings with many
    facades."""
    widths, depths = _blocks(rng, (4, 6), (70, 90)), _blocks(rng, (3, 5), (70, 90))
    lo = int(rng.integers(2, 4))
    return {
        "style": "town",
        "block_widths_m": widths,
        "block_depths_m": depths,
        "border_m": 40.0,
        "parks": _parks(rng, len(widths), len(depths), float(rng.uniform(0.1, 0.2))),
        "buildings": {
            "floors": [lo, lo + int(rng.integers(1, 3))],
            "frontage_m": [float(rng.uniform(7, 10)), float(rng.uniform(16, 20))],
            "depth_m": [9.0, float(rng.uniform(12, 15))],
            "gap_probability": float(rng.uniform(0.1, 0.2)),
            "facade_styles": int(rng.integers(20, 33)),
            "shop_probability": float(rng.uniform(0.6, 0.9)),
            "shop_styles": int(rng.integers(32, 65)),
        },
        "props": {
            "tree_spacing_m": float(rng.uniform(13, 19)),
            "lamp_spacing_m": float(rng.uniform(25, 35)),
            "parked_car_probability": float(rng.uniform(0.4, 0.8)),
        },
    }


def _city_style(rng: np.random.Generator) -> dict[str, Any]:
    """Ranges around town10: 4-5 x 3-4 blocks of 65-85 m, avenues with two lanes each way, a
    beach on one side or none, 30-50 % of blocks with towers, 3-6 facade styles."""
    widths, depths = _blocks(rng, (4, 5), (65, 85)), _blocks(rng, (3, 4), (65, 85))
    return {
        "style": "city",
        "block_widths_m": widths,
        "block_depths_m": depths,
        "border_m": 45.0,
        "beach_side": str(rng.choice(["none", "south", "north", "west", "east"])),
        "road": {"lane_width_m": 3.75, "lanes_per_direction": 2},
        "buildings": {
            "floors": [int(rng.integers(4, 7)), int(rng.integers(10, 14))],
            "frontage_m": [float(rng.uniform(14, 18)), float(rng.uniform(26, 32))],
            "depth_m": [12.0, float(rng.uniform(16, 20))],
            "gap_probability": float(rng.uniform(0.03, 0.08)),
            "tower_block_fraction": float(rng.uniform(0.3, 0.5)),
            "tower_floors": [int(rng.integers(15, 21)), int(rng.integers(35, 50))],
            "facade_styles": int(rng.integers(3, 7)),
            "shop_probability": float(rng.uniform(0.6, 0.9)),
        },
        "props": {
            "tree_spacing_m": float(rng.uniform(17, 23)),
            "lamp_spacing_m": float(rng.uniform(22, 28)),
            "bollard_spacing_m": 6.0,
            "parked_car_probability": float(rng.uniform(0.2, 0.4)),
        },
    }


def _right_side(a: tuple[int, int], b: tuple[int, int], nx_: int, ny_: int) -> list[Any]:
    """What a right-facing camera sees along the street a -> b: block indices (i, j), or the
    border strip's side (``"south"``, ...) where the street is the ring road."""
    (i0, j0), (i1, j1) = a, b
    if j0 == j1:  # along x: moving +x the right is south (-y)
        j = j0 - 1 if i1 > i0 else j0
        side = [(i, j) for i in range(min(i0, i1), max(i0, i1))]
        border = "south" if j < 0 else "north" if j >= ny_ else None
    else:  # along y: moving +y the right is east (+x)
        i = i0 if j1 > j0 else i0 - 1
        side = [(i, j) for j in range(min(j0, j1), max(j0, j1))]
        border = "west" if i < 0 else "east" if i >= nx_ else None
    return [border] if border else side


def _draw_route(
    rng: np.random.Generator, data: dict[str, Any], length_m: float, turns: int
) -> dict[str, Any] | None:
    """A route through the grid with ``turns`` 90-degree turns, about ``length_m`` long, that never
    passes an intersection twice and keeps buildings on its right; None when this layout's draws
    found none."""
    widths, depths = data["block_widths_m"], data["block_depths_m"]
    layout = road_layout(widths, depths, RoadSpec(**data.get("road", {})))
    nx_, ny_ = len(widths), len(depths)
    bad_sides = {tuple(p) for p in data.get("parks", [])} | {data.get("beach_side", "none")}
    for _ in range(50):
        # legs as long as the route needs on average: 2.5 blocks in a town, 1 in a city
        leg_blocks = length_m / ((turns + 1) * float(np.mean([*widths, *depths])))
        nodes = _walk(rng, nx_ + 1, ny_ + 1, turns, leg_blocks)
        if nodes is None or any(
            part in bad_sides
            for a, b in itertools.pairwise(nodes)
            for part in _right_side(a, b, nx_, ny_)
        ):
            continue
        offsets = _fit_offsets(layout, nodes, length_m)
        if offsets is not None:
            return {
                "nodes": [list(n) for n in nodes],
                "start_offset_m": offsets[0],
                "end_offset_m": offsets[1],
                "target_length_m": length_m,
            }
    return None


def _walk(
    rng: np.random.Generator, ni: int, nj: int, turns: int, leg_blocks: float
) -> list[tuple[int, int]] | None:
    """Intersections of a walk with a 90-degree turn at each inner node, its legs about
    ``leg_blocks`` long (1 + Poisson, among the legs that stay in the grid), that never comes back
    to an intersection it passed; None when it is boxed in."""
    node = (int(rng.integers(0, ni)), int(rng.integers(0, nj)))
    nodes, seen = [node], {node}
    axis = int(rng.integers(0, 2))
    mean_extra = max(leg_blocks - 1, 0.0)
    for _ in range(turns + 1):
        legs, weights = [], []
        for sign in (-1, 1):
            step = (sign, 0) if axis == 0 else (0, sign)
            path: list[tuple[int, int]] = []
            for k in range(1, max(ni, nj)):
                nxt = (node[0] + k * step[0], node[1] + k * step[1])
                if not (0 <= nxt[0] < ni and 0 <= nxt[1] < nj) or nxt in seen:
                    break
                path.append(nxt)
                legs.append(list(path))
                weights.append(mean_extra ** (k - 1) / math.factorial(k - 1))
        if not legs:
            return None
        path = legs[int(rng.choice(len(legs), p=np.divide(weights, sum(weights))))]
        seen.update(path)
        node = path[-1]
        nodes.append(node)
        axis = 1 - axis
    return nodes


def _fit_offsets(
    layout: RoadLayout, nodes: list[tuple[int, int]], length_m: float
) -> tuple[float, float] | None:
    """Start and end offsets (m) that bring the route through ``nodes`` within :data:`ROUTE_FIT`
    of ``length_m``, or None if no offsets in their allowed ranges do."""
    zone = layout.zone_m
    first = float(np.linalg.norm(layout.center(nodes[1]) - layout.center(nodes[0])))
    last = float(np.linalg.norm(layout.center(nodes[-1]) - layout.center(nodes[-2])))
    room = (first - 3 * zone, last - 3 * zone)  # how far each end can move in
    if min(room) < 0:
        return None
    longest = build_route(layout, tuple(nodes), zone, zone).length_m
    cut = longest - length_m
    if not 0 <= cut <= sum(room):
        return None
    share = cut / sum(room) if sum(room) > 0 else 0.0
    start, end = round(zone + share * room[0], 1), round(zone + share * room[1], 1)
    route_m = build_route(layout, tuple(nodes), start, end).length_m
    return (start, end) if abs(route_m - length_m) <= ROUTE_FIT * length_m else None
