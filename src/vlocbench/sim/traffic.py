"""Dynamic objects: cars that follow random routes over the lane graph, pedestrians on sidewalks.

Seeded and stepped in lock-step with the simulation. Cars keep their distance to the car ahead and to
the ego car (they brake when something is less than ``gap_m`` ahead in their lane).
"""

from __future__ import annotations

import networkx as nx
import numpy as np

from vlocbench.geometry import polyline_length, resample_polyline
from vlocbench.interfaces import Array
from vlocbench.sim.conditions import Traffic
from vlocbench.sim.town import Town


class _PathFollower:
    """Moves along a polyline that is extended on demand."""

    def __init__(self, points: Array, s: float) -> None:
        self.points = points
        self.s = s
        self._update()

    def _update(self) -> None:
        seg = np.linalg.norm(np.diff(self.points, axis=0), axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(seg)])

    def pose(self) -> tuple[float, float, float]:
        s = float(np.clip(self.s, 0, self.cum[-1]))
        k = int(np.clip(np.searchsorted(self.cum, s, side="right") - 1, 0, len(self.points) - 2))
        t = (s - self.cum[k]) / max(1e-9, self.cum[k + 1] - self.cum[k])
        p = self.points[k] + t * (self.points[k + 1] - self.points[k])
        d = self.points[k + 1] - self.points[k]
        return float(p[0]), float(p[1]), float(np.arctan2(d[1], d[0]))

    def remaining(self) -> float:
        return float(self.cum[-1] - self.s)


class TrafficModel:
    """Positions of ``config.cars`` cars and ``config.pedestrians`` pedestrians over time."""

    def __init__(self, town: Town, config: Traffic, avoid_xy: Array | None = None) -> None:
        self.config = config
        self.rng = np.random.default_rng(config.seed)
        self.graph: nx.DiGraph = town.lane_graph
        edges = [e for e in self.graph.edges if self.graph.edges[e]["kind"] == "lane"]
        self.cars: list[tuple[_PathFollower, tuple]] = []
        for _ in range(config.cars):
            for _attempt in range(20):
                e = edges[int(self.rng.integers(len(edges)))]
                line = self.graph.edges[e]["polyline"]
                s = float(self.rng.uniform(0, polyline_length(line)))
                follower = _PathFollower(line.copy(), s)
                x, y, _ = follower.pose()
                # keep clear of the ego start and of other cars
                others = [c.pose()[:2] for c, _ in self.cars]
                if avoid_xy is not None:
                    others.append(tuple(avoid_xy))
                if all(np.hypot(x - ox, y - oy) > 15 for ox, oy in others):
                    break
            self.cars.append((follower, e[1]))
        loops = town.sidewalk_loops()
        self.pedestrians: list[tuple[_PathFollower, float]] = []
        for _ in range(config.pedestrians if loops else 0):
            loop = loops[int(self.rng.integers(len(loops)))]
            if self.rng.random() < 0.5:
                loop = loop[::-1]
            line = resample_polyline(loop, 1.0)
            line = np.concatenate([line] * 50)  # walk round the block many times
            start = float(self.rng.uniform(0, polyline_length(loop)))
            speed = config.pedestrian_speed_mps * float(self.rng.uniform(0.8, 1.2))
            self.pedestrians.append((_PathFollower(line, start), speed))

    def _extend(self, follower: _PathFollower, node: tuple) -> tuple:
        """Append a random successor edge of ``node`` to the path; drop the path behind."""
        succ = sorted(self.graph.successors(node))
        nxt = succ[int(self.rng.integers(len(succ)))]
        line = self.graph.edges[node, nxt]["polyline"]
        k = max(0, int(np.searchsorted(follower.cum, follower.s, side="right")) - 2)
        follower.s -= follower.cum[k]
        follower.points = np.concatenate([follower.points[k:], line[1:]])
        follower._update()
        return nxt

    def step(self, dt_s: float, ego_xy: Array) -> None:
        poses = self.car_poses()
        for k, (follower, node) in enumerate(self.cars):
            x, y, yaw = poses[k]
            heading = np.array([np.cos(yaw), np.sin(yaw)])
            blocked = False
            for ox, oy in [*(p[:2] for j, p in enumerate(poses) if j != k), tuple(ego_xy)]:
                rel = np.array([ox - x, oy - y])
                ahead = rel @ heading
                if 0 < ahead < 9.0 and abs(heading[0] * rel[1] - heading[1] * rel[0]) < 2.2:
                    blocked = True
            if not blocked:
                follower.s += self.config.car_speed_mps * dt_s
            while follower.remaining() < 1.0:
                node = self._extend(follower, node)
            self.cars[k] = (follower, node)
        for follower, speed in self.pedestrians:
            follower.s += speed * dt_s

    def car_poses(self) -> list[tuple[float, float, float]]:
        return [f.pose() for f, _ in self.cars]

    def pedestrian_poses(self) -> list[tuple[float, float, float]]:
        return [f.pose() for f, _ in self.pedestrians]
