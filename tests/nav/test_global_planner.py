import networkx as nx
import numpy as np
import pytest

from vlocbench.errors import ConfigError, PlanningError
from vlocbench.geometry import resample_polyline
from vlocbench.nav import GlobalPlanner, WaypointPath


def _graph(edges):
    """A lane graph from {(u, v): [points]}; node positions from the polyline ends."""
    g = nx.DiGraph()
    for (u, v), pts in edges.items():
        line = resample_polyline(np.asarray(pts, dtype=float), 2.0)
        g.add_node(u, xy=line[0])
        g.add_node(v, xy=line[-1])
        g.add_edge(
            u, v, polyline=line, length_m=float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
        )
    return g


# one-way square A(0,0) -> B(100,0) -> C(100,100) -> D(0,100) -> A, plus a diagonal shortcut A -> C
SQUARE = {
    ("A", "B"): [(0, 0), (100, 0)],
    ("B", "C"): [(100, 0), (100, 100)],
    ("C", "D"): [(100, 100), (0, 100)],
    ("D", "A"): [(0, 100), (0, 0)],
    ("A", "C"): [(0, 0), (100, 100)],
}


def test_astar_takes_the_shortest_route_and_respects_one_way_lanes():
    planner = GlobalPlanner(_graph(SQUARE))
    # from the middle of D->A to the middle of C->D: A, then the diagonal to C, then C->D
    path = planner.plan([(0, 50), (50, 100)])
    # (resampling every 2 m cuts the corners by a few decimetres)
    assert path.length_m == pytest.approx(50 + 100 * np.sqrt(2) + 50, abs=1.5)
    steps = np.diff(path.s_m)
    assert np.all(steps <= 2.0 + 1e-9) and np.median(steps) == pytest.approx(2.0)
    # going "backwards" along a one-way lane needs the whole loop
    back = planner.plan([(0, 40), (0, 60)])  # D->A runs from y = 100 down to y = 0
    assert back.length_m > 200


def test_via_points_force_the_route_through_them():
    planner = GlobalPlanner(_graph(SQUARE))
    direct = planner.plan([(0, 50), (50, 100)])  # takes the diagonal
    via = planner.plan([(0, 50), (100, 50), (50, 100)])  # must go round by B and C
    assert via.length_m == pytest.approx(300, abs=1.5)
    assert direct.length_m < via.length_m
    assert min(np.hypot(*(p - (100, 50))) for p in via.xy) < 1.0


def test_same_lane_leg_and_snap_distance():
    planner = GlobalPlanner(_graph(SQUARE), max_snap_m=3.0)
    path = planner.plan([(10, 1), (30, -1)])  # both snap onto A->B
    assert path.length_m == pytest.approx(20, abs=1e-6)
    with pytest.raises(PlanningError, match="from the nearest lane"):
        planner.plan([(50, 50.0 + 20), (10, 0)])


def test_unreachable_and_bad_input():
    g = _graph({("A", "B"): [(0, 0), (50, 0)], ("C", "D"): [(0, 20), (50, 20)]})
    with pytest.raises(PlanningError, match="no lane path"):
        GlobalPlanner(g).plan([(10, 0), (10, 20)])
    with pytest.raises(ConfigError, match="points_xy"):
        GlobalPlanner(g).plan([(10, 0)])
    with pytest.raises(ConfigError, match="path"):
        WaypointPath(np.zeros((1, 2)))


def test_town_route_is_reproduced_from_its_via_points(small_town):
    path = GlobalPlanner(small_town.lane_graph).plan(small_town.route.via_points(small_town.layout))
    ref = WaypointPath(small_town.route.waypoints_xy)
    assert path.length_m == pytest.approx(ref.length_m, rel=0.01)
    assert max(ref.project(p).distance_m for p in path.xy) < 0.2
    assert max(path.project(p).distance_m for p in ref.xy) < 0.2
