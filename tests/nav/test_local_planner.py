import numpy as np
import pytest

from tests.nav.paths import straight
from vlocbench.errors import ConfigError
from vlocbench.nav import LocalPlanner, LocalPlannerConfig, WaypointPath

BAND = LocalPlannerConfig(rule="band")


def test_paper_rule_targets_the_first_waypoint_at_least_0_9_s_ahead():
    planner = LocalPlanner(straight(100.0), target_speed_mps=4.0)
    ahead = []
    for x in np.arange(0.0, 60.0, 0.2):  # drive along at 4 m/s, 20 Hz, 0.3 m off the path
        t = planner.step(np.array([x, 0.3]), 4.0)
        d = np.hypot(t.xy[0] - x, 0.3)
        assert 3.6 <= d < 3.6 + 2.0 + 1e-9  # the first waypoint at least 3.6 m away
        ahead.append(d)
    assert np.mean(ahead) == pytest.approx(4.6, abs=0.1)


def test_paper_rule_searches_again_beyond_3_s_and_takes_the_goal_at_the_end():
    planner = LocalPlanner(straight(100.0), target_speed_mps=4.0)
    assert planner.step(np.array([0.0, 0.0]), 0.0).xy[0] == pytest.approx(4.0)
    # the estimate jumps 20 m ahead: the old target is 16 m behind (> 12 m), so the closest
    # waypoint is taken, and the next step moves on from there
    t = planner.step(np.array([24.1, 0.0]), 4.0)
    assert t.xy[0] == pytest.approx(24.0)
    assert planner.step(np.array([24.1, 0.0]), 4.0).xy[0] == pytest.approx(28.0)
    planner.reset(95.0)
    assert planner.step(np.array([97.0, 0.0]), 4.0).index == len(planner.path) - 1


def test_target_stays_in_the_lookahead_band():
    planner = LocalPlanner(straight(100.0), BAND)
    speed = 4.0
    near, far = planner.band_m(speed)
    assert (near, far) == pytest.approx((3.6, 12.0))
    targets = []
    for x in np.arange(0.0, 60.0, 0.2):  # drive along at 4 m/s, 20 Hz
        t = planner.step(np.array([x, 0.3]), speed)
        ahead = t.xy[0] - x
        assert near - 1e-9 <= ahead <= far + 1e-9
        assert t.offset_m == pytest.approx(0.3)
        targets.append(t.index)
    # kept while inside the band, recomputed (to the far edge) when it falls out
    assert np.all(np.diff(targets) >= 0)
    changes = np.flatnonzero(np.diff(targets))
    assert 5 <= len(changes) <= 10
    assert planner.path.xy[targets[0], 0] == pytest.approx(12.0)


def test_band_has_a_floor_at_rest_and_targets_the_goal_at_the_end():
    planner = LocalPlanner(straight(100.0), BAND)
    near, far = planner.band_m(0.0)
    assert near == pytest.approx(3.0) and far > near
    t = planner.step(np.array([0.0, 0.0]), 0.0)
    assert 3.0 <= t.xy[0] <= far
    planner.reset(95.0)
    t = planner.step(np.array([98.0, 0.0]), 4.0)
    assert t.index == len(planner.path) - 1
    assert t.remaining_m == pytest.approx(2.0)


def test_closest_waypoint_is_searched_over_the_route_or_in_a_window():
    # an out-and-back route: the return leg runs 1 m beside the outward one
    out = np.stack([np.arange(0, 51, 2.0), np.zeros(26)], 1)
    back = np.stack([np.arange(50, -1, -2.0), np.ones(26)], 1)
    path = WaypointPath(np.vstack([out, [[52.0, 0.5]], back]))
    xy = np.array([10.0, 0.9])  # nearer the return leg, but the drive has just started
    # the paper's planner: the nearest waypoint of the whole route, on the return leg
    paper = LocalPlanner(path, LocalPlannerConfig()).step(xy, 4.0)
    assert paper.s_closest_m > 60 and paper.xy[1] == 1.0
    for config in (
        LocalPlannerConfig(rule="band", search="window"),
        LocalPlannerConfig(search="window"),
    ):
        t = LocalPlanner(path, config).step(xy, 4.0)
        assert t.s_closest_m < 20 and t.xy[1] == 0.0


def test_bad_config():
    with pytest.raises(ConfigError, match="max_lookahead_s"):
        LocalPlannerConfig(min_lookahead_s=2.0, max_lookahead_s=1.0)
    with pytest.raises(ConfigError, match=r"local_planner\.rule"):
        LocalPlannerConfig(rule="carrot")
    with pytest.raises(ConfigError, match=r"local_planner\.search.*valid: route, window"):
        LocalPlannerConfig(search="nearby")


def test_head_of_a_path():
    path = straight(100.0)
    head = path.head(31.0)
    assert head.length_m == 32.0  # up to the first waypoint at or past 31 m
    assert path.head(0.0) is path and path.head(500.0) is path
