"""Global planner: the shortest drivable route over a directed lane graph (networkx A*).

The graph follows the contract of ``sim.roads.build_lane_graph`` without importing it: nodes carry
``xy`` (2,) and edges carry ``polyline`` ((K, 2), ordered along the direction of travel) and
``length_m``. Start, goal and intermediate points are free positions; each is snapped to the
closest lane (so its direction of travel is the lane's).
"""

from __future__ import annotations

import itertools
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import networkx as nx
import numpy as np

from vlocbench.errors import ConfigError, PlanningError
from vlocbench.geometry import resample_polyline
from vlocbench.interfaces import Array
from vlocbench.nav.path import WaypointPath


@dataclass(frozen=True)
class LanePoint:
    """A position snapped onto lane ``edge`` at arc length ``s_m``, ``offset_m`` away from it."""

    edge: tuple[Hashable, Hashable]
    s_m: float
    offset_m: float


class GlobalPlanner:
    """Plans over ``graph``; ``max_snap_m`` bounds how far a point may lie from every lane."""

    def __init__(self, graph: nx.DiGraph, spacing_m: float = 2.0, max_snap_m: float = 10.0) -> None:
        if spacing_m <= 0:
            raise ConfigError("spacing_m", f"must be > 0, got {spacing_m}")
        if graph.number_of_edges() == 0:
            raise ConfigError("graph", "has no lanes")
        self.graph = graph
        self.spacing_m = spacing_m
        self.max_snap_m = max_snap_m
        starts, ends, owner, s0 = [], [], [], []
        self._edges = list(graph.edges)
        for k, (u, v) in enumerate(self._edges):
            line = np.asarray(graph.edges[u, v]["polyline"], dtype=np.float64)
            seg_len = np.linalg.norm(np.diff(line, axis=0), axis=1)
            starts.append(line[:-1])
            ends.append(line[1:])
            owner.append(np.full(len(line) - 1, k))
            s0.append(np.concatenate([[0.0], np.cumsum(seg_len)[:-1]]))
        self._seg_a = np.concatenate(starts)
        self._seg_d = np.concatenate(ends) - self._seg_a
        self._seg_owner = np.concatenate(owner)
        self._seg_s0 = np.concatenate(s0)

    def snap(self, xy: Array) -> LanePoint:
        """The closest lane position to ``xy`` (2,)."""
        rel = np.asarray(xy, dtype=np.float64) - self._seg_a
        len2 = np.einsum("ij,ij->i", self._seg_d, self._seg_d)
        t = np.clip(np.einsum("ij,ij->i", rel, self._seg_d) / np.maximum(len2, 1e-12), 0.0, 1.0)
        dist = np.linalg.norm(rel - self._seg_d * t[:, None], axis=1)
        k = int(np.argmin(dist))
        if dist[k] > self.max_snap_m:
            raise PlanningError(
                f"point ({xy[0]:.1f}, {xy[1]:.1f}) is {dist[k]:.1f} m from the nearest lane "
                f"(at most {self.max_snap_m:g} m)"
            )
        s = self._seg_s0[k] + t[k] * np.sqrt(len2[k])
        return LanePoint(self._edges[self._seg_owner[k]], float(s), float(dist[k]))

    def _heuristic(self, a: Hashable, b: Hashable) -> float:
        return float(np.linalg.norm(self.graph.nodes[a]["xy"] - self.graph.nodes[b]["xy"]))

    def _piece(self, edge: tuple[Hashable, Hashable], s_from: float, s_to: float) -> Array:
        line = np.asarray(self.graph.edges[edge]["polyline"], dtype=np.float64)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(line, axis=0), axis=1))])
        inner = line[(s > s_from) & (s < s_to)]
        ends = [np.interp(v, s, line[:, i]) for v in (s_from, s_to) for i in (0, 1)]
        return np.vstack([ends[:2], inner, ends[2:]])

    def _leg(self, a: LanePoint, b: LanePoint) -> Array:
        if a.edge == b.edge and b.s_m >= a.s_m:
            return self._piece(a.edge, a.s_m, b.s_m)
        try:
            nodes = nx.astar_path(
                self.graph, a.edge[1], b.edge[0], heuristic=self._heuristic, weight="length_m"
            )
        except nx.NetworkXNoPath:
            raise PlanningError(f"no lane path from {a.edge[1]} to {b.edge[0]}") from None
        pieces = [self._piece(a.edge, a.s_m, np.inf)]
        pieces += [self.graph.edges[u, v]["polyline"] for u, v in itertools.pairwise(nodes)]
        pieces.append(self._piece(b.edge, 0.0, b.s_m))
        return np.vstack(pieces)

    def plan(self, points_xy: Sequence[Array] | Array) -> WaypointPath:
        """Shortest route from the first point to the last through the others, in order.

        Returns waypoints every ``spacing_m`` on the lanes (the last step may be shorter).
        """
        points = np.asarray(points_xy, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
            raise ConfigError("points_xy", f"needs (N >= 2, 2) positions, got shape {points.shape}")
        snapped = [self.snap(p) for p in points]
        legs = [self._leg(a, b) for a, b in itertools.pairwise(snapped)]
        return WaypointPath(resample_polyline(np.vstack(legs), self.spacing_m))
