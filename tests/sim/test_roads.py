import networkx as nx
import numpy as np

from vlocbench.geometry import resample_polyline


def test_resample_keeps_ends_and_spacing():
    line = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 5.0]])
    out = resample_polyline(line, 2.0)
    np.testing.assert_allclose(out[0], [0, 0])
    np.testing.assert_allclose(out[-1], [10, 5])
    assert len(out) == 9  # 15 m at 2 m


def test_lane_graph_is_strongly_connected_and_right_handed(small_town):
    g = small_town.lane_graph
    assert nx.is_strongly_connected(g)
    kinds = {d["kind"] for _, _, d in g.edges(data=True)}
    assert kinds == {"lane", "straight", "left", "right"}
    # an eastbound lane lies south of its road's centre line (right-hand traffic)
    for u, _v, d in g.edges(data=True):
        if d["kind"] == "lane" and u[3] == "E":
            y_road = small_town.layout.ys[u[2]]
            assert np.allclose(d["polyline"][:, 1], y_road - small_town.layout.lane_offset_m)


def test_turn_arcs_have_the_expected_radius(small_town):
    lay = small_town.layout
    g = small_town.lane_graph
    for _u, _v, d in g.edges(data=True):
        if d["kind"] in ("left", "right"):
            expected = lay.zone_m + (
                lay.lane_offset_m if d["kind"] == "left" else -lay.lane_offset_m
            )
            np.testing.assert_allclose(d["length_m"], np.pi / 2 * expected, rtol=0.02)
