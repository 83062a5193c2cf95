"""Road network of a grid town: intersections, right-hand lanes, turn connectors, routes.

Pure numerics. Roads run along the grid lines ``x = xs[i]`` and ``y = ys[j]``; every road has
``lanes_per_direction`` lanes each way (right-hand traffic), and the lane graph follows the lane next
to the centre line (on a wide road the car has the outer lanes to its right before the curb, as on
CARLA Town10's avenues). Around each intersection centre lies a square zone of
half-size ``zone_m = half road width + corner radius``; inside it lanes are joined by connectors
(straight, or quarter arcs of radius ``zone_m - lane_offset`` for right turns and
``zone_m + lane_offset`` for left turns). Lane polylines are sampled every ``spacing_m`` (2 m).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import networkx as nx
import numpy as np

from vlocbench.errors import ConfigError
from vlocbench.geometry import headings_of, polyline_length, resample_polyline
from vlocbench.interfaces import Array

# unit headings: east, north, west, south
HEADINGS: dict[str, tuple[int, int]] = {"E": (1, 0), "N": (0, 1), "W": (-1, 0), "S": (0, -1)}


def _right(h: Array) -> Array:
    return np.array([h[1], -h[0]], dtype=np.float64)


def _arc(center: Array, start: Array, sweep_rad: float, step_m: float = 0.5) -> Array:
    radius = float(np.linalg.norm(start - center))
    a0 = float(np.arctan2(start[1] - center[1], start[0] - center[0]))
    n = max(2, int(np.ceil(abs(sweep_rad) * radius / step_m)) + 1)
    a = a0 + np.linspace(0.0, sweep_rad, n)
    return center + radius * np.stack([np.cos(a), np.sin(a)], axis=1)


@dataclass(frozen=True)
class RoadLayout:
    """Geometry of the road grid. ``xs``/``ys``: (I,), (J,) road centre lines in metres."""

    xs: Array
    ys: Array
    lane_width_m: float
    corner_radius_m: float
    lanes_per_direction: int = 1

    @property
    def half_width_m(self) -> float:
        return self.lanes_per_direction * self.lane_width_m

    @property
    def lane_offset_m(self) -> float:
        """From the centre line to the middle of the driven lane (the innermost one)."""
        return 0.5 * self.lane_width_m

    @property
    def zone_m(self) -> float:
        return self.half_width_m + self.corner_radius_m

    def center(self, node: tuple[int, int]) -> Array:
        i, j = node
        return np.array([self.xs[i], self.ys[j]], dtype=np.float64)

    def has_node(self, node: tuple[int, int]) -> bool:
        i, j = node
        return 0 <= i < len(self.xs) and 0 <= j < len(self.ys)

    def arrival(self, node: tuple[int, int], heading: Array) -> Array:
        """Where a lane moving along ``heading`` enters the zone of ``node``."""
        return self.center(node) - heading * self.zone_m + _right(heading) * self.lane_offset_m

    def departure(self, node: tuple[int, int], heading: Array) -> Array:
        """Where a lane moving along ``heading`` leaves the zone of ``node``."""
        return self.center(node) + heading * self.zone_m + _right(heading) * self.lane_offset_m

    def lane_midpoint(self, a: tuple[int, int], b: tuple[int, int]) -> Array:
        """The middle of the right-hand lane from intersection ``a`` to neighbouring ``b``."""
        d = self.center(b) - self.center(a)
        return (
            0.5 * (self.center(a) + self.center(b))
            + _right(d / np.linalg.norm(d)) * self.lane_offset_m
        )

    def connector(self, node: tuple[int, int], h_in: Array, h_out: Array) -> Array:
        """Polyline (N, 2) through the zone of ``node`` from heading ``h_in`` to ``h_out``."""
        p0 = self.arrival(node, h_in)
        p1 = self.departure(node, h_out)
        cross = h_in[0] * h_out[1] - h_in[1] * h_out[0]
        if abs(cross) < 0.5:  # straight on
            return np.stack([p0, p1])
        left = cross > 0
        radius = self.zone_m + self.lane_offset_m if left else self.zone_m - self.lane_offset_m
        normal = -_right(h_in) if left else _right(h_in)
        return _arc(p0 + normal * radius, p0, np.pi / 2 if left else -np.pi / 2)


def build_lane_graph(layout: RoadLayout, spacing_m: float = 2.0) -> nx.DiGraph:
    """Directed lane graph of a full grid of roads.

    Nodes: ``("in", i, j, d)`` where a lane heading ``d`` enters intersection (i, j)'s zone, and
    ``("out", i, j, d)`` where it leaves; attribute ``xy`` (2,). Edges carry ``polyline`` ((N, 2),
    every ``spacing_m``), ``length_m`` and ``kind`` in {lane, straight, left, right}.
    """
    graph = nx.DiGraph()
    ni, nj = len(layout.xs), len(layout.ys)
    for i in range(ni):
        for j in range(nj):
            for d, (dx, dy) in HEADINGS.items():
                h = np.array([dx, dy], dtype=np.float64)
                nxt = (i + dx, j + dy)
                if layout.has_node(nxt):  # a lane leaves (i, j) towards nxt
                    a, b = layout.departure((i, j), h), layout.arrival(nxt, h)
                    out, inn = ("out", i, j, d), ("in", *nxt, d)
                    graph.add_node(out, xy=a)
                    graph.add_node(inn, xy=b)
                    line = resample_polyline(np.stack([a, b]), spacing_m)
                    graph.add_edge(
                        out, inn, polyline=line, length_m=polyline_length(line), kind="lane"
                    )
    for node in list(graph.nodes):
        kind, i, j, d = node
        if kind != "in":
            continue
        h_in = np.array(HEADINGS[d], dtype=np.float64)
        for d2, (dx, dy) in HEADINGS.items():
            h_out = np.array([dx, dy], dtype=np.float64)
            if h_in @ h_out < -0.5 or ("out", i, j, d2) not in graph:  # no U-turns
                continue
            cross = h_in[0] * h_out[1] - h_in[1] * h_out[0]
            turn = "straight" if abs(cross) < 0.5 else ("left" if cross > 0 else "right")
            line = resample_polyline(layout.connector((i, j), h_in, h_out), spacing_m)
            graph.add_edge(
                node, ("out", i, j, d2), polyline=line, length_m=polyline_length(line), kind=turn
            )
    return graph


@dataclass(frozen=True)
class Route:
    """A drivable route along right-hand lanes.

    ``waypoints_xy``: (N, 2) every ``spacing_m`` (the last step may be shorter);
    ``yaw_rad``: (N,) heading at each waypoint; ``nodes``: the intersections it turns at.
    """

    waypoints_xy: Array
    yaw_rad: Array
    nodes: tuple[tuple[int, int], ...]
    spacing_m: float

    @property
    def length_m(self) -> float:
        return polyline_length(self.waypoints_xy)

    @property
    def num_turns(self) -> int:
        return max(0, len(self.nodes) - 2)

    def via_points(self, layout: RoadLayout) -> Array:
        """(K, 2) points that pin this route down for a shortest-path planner: its start, the
        middle of every block it drives along (bar the first and last, which hold the start and
        the end), its end."""
        blocks = []
        for a, b in itertools.pairwise(self.nodes):
            step = np.sign(np.subtract(b, a)).astype(int)
            n = int(np.abs(np.subtract(b, a)).sum())
            blocks += [
                (tuple(np.add(a, k * step)), tuple(np.add(a, (k + 1) * step))) for k in range(n)
            ]
        inner = [layout.lane_midpoint(a, b) for a, b in blocks[1:-1]]
        return np.vstack([self.waypoints_xy[:1], *inner, self.waypoints_xy[-1:]])


def build_route(
    layout: RoadLayout,
    nodes: tuple[tuple[int, int], ...],
    start_offset_m: float,
    end_offset_m: float,
    spacing_m: float = 2.0,
    field: str = "route",
) -> Route:
    """Route through grid intersections ``nodes``, turning 90 degrees at each inner node.

    It starts ``start_offset_m`` past ``nodes[0]`` on the first leg and ends ``end_offset_m``
    before ``nodes[-1]``; both offsets must keep clear of the intersection zones.
    """
    if len(nodes) < 2:
        raise ConfigError(f"{field}.nodes", "needs at least two intersections")
    for k, node in enumerate(nodes):
        if not layout.has_node(node):
            raise ConfigError(
                f"{field}.nodes[{k}]",
                f"{node} is outside the grid of {len(layout.xs)}x{len(layout.ys)} intersections",
            )
    headings = []
    for k in range(len(nodes) - 1):
        d = np.array(nodes[k + 1], dtype=np.float64) - np.array(nodes[k], dtype=np.float64)
        if (d[0] != 0) == (d[1] != 0):
            raise ConfigError(
                f"{field}.nodes[{k + 1}]", "consecutive nodes must share a row or a column"
            )
        headings.append(d / np.linalg.norm(d))
    for k in range(1, len(headings)):
        if abs(headings[k - 1] @ headings[k]) > 0.5:
            raise ConfigError(f"{field}.nodes[{k}]", "every inner node must be a 90-degree turn")
    first_len = float(np.linalg.norm(layout.center(nodes[1]) - layout.center(nodes[0])))
    last_len = float(np.linalg.norm(layout.center(nodes[-1]) - layout.center(nodes[-2])))
    zone = layout.zone_m
    if not zone <= start_offset_m <= first_len - zone - (0 if len(nodes) == 2 else zone):
        raise ConfigError(
            f"{field}.start_offset_m",
            f"must lie in [{zone:g}, {first_len - 2 * zone:g}] to stay clear of intersections",
        )
    if not zone <= end_offset_m <= last_len - 2 * zone:
        raise ConfigError(
            f"{field}.end_offset_m",
            f"must lie in [{zone:g}, {last_len - 2 * zone:g}] to stay clear of intersections",
        )
    h0, hn = headings[0], headings[-1]
    start = layout.center(nodes[0]) + h0 * start_offset_m + _right(h0) * layout.lane_offset_m
    end = layout.center(nodes[-1]) - hn * end_offset_m + _right(hn) * layout.lane_offset_m
    pieces = [start[None]]
    for k in range(1, len(nodes) - 1):
        pieces.append(layout.connector(nodes[k], headings[k - 1], headings[k]))
    pieces.append(end[None])
    waypoints = resample_polyline(np.concatenate(pieces), spacing_m)
    return Route(waypoints, headings_of(waypoints), tuple(nodes), spacing_m)
