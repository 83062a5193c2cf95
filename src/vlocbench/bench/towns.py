"""Towns and their test routes by name, generated once per process.

A town is a pure function of its spec, so every part of a run (driver, workers, report) may ask for
it by name and gets the same layout; the cache saves regenerating it for every episode.
"""

from __future__ import annotations

from functools import lru_cache

from vlocbench.nav import GlobalPlanner, WaypointPath
from vlocbench.sim.town import Town, generate_town, load_town_spec


def plan_town_route(town: Town, spacing_m: float = 2.0) -> WaypointPath:
    """The town's test route as the global planner finds it: start, each leg, goal."""
    return GlobalPlanner(town.lane_graph, spacing_m).plan(town.route.via_points(town.layout))


@lru_cache(maxsize=8)
def town_named(name: str) -> Town:
    """A built-in town (``town01``) or the town of a spec YAML path."""
    return generate_town(load_town_spec(name))


@lru_cache(maxsize=8)
def route_named(name: str, length_m: float = 0.0) -> WaypointPath:
    """The route of :func:`town_named`'s town, cut after its first ``length_m`` metres when that is
    > 0 (waypoints 2 m apart)."""
    return plan_town_route(town_named(name)).head(length_m)
