import numpy as np
import pytest

from tests.nav.paths import straight
from vlocbench.errors import ConfigError
from vlocbench.nav import FailureConfig, FailureDetector, ProgressTracker, WaypointPath


def test_progress_counts_only_near_the_route():
    tracker = ProgressTracker(straight(400.0))
    tracker.update(np.array([20.5, 1.0]))
    assert tracker.farthest_s_m == pytest.approx(20.5)
    assert tracker.farthest_index == 10  # waypoint at x = 20, the farthest one reached
    tracker.update(np.array([40.0, 4.5]))  # more than 4 m off the route: no progress
    assert tracker.farthest_s_m == pytest.approx(20.5)
    tracker.update(np.array([40.0, 3.9]))
    assert tracker.farthest_s_m == pytest.approx(40.0)
    tracker.update(np.array([10.0, 0.0]))  # going back never loses progress
    assert tracker.farthest_s_m == pytest.approx(40.0)


def test_progress_never_jumps_more_than_150_m():
    # a U-shaped route: the far end passes 3 m from its start
    out = np.stack([np.arange(0, 201, 2.0), np.zeros(101)], 1)
    back = np.stack([np.arange(200, -1, -2.0), np.full(101, 3.0)], 1)
    path = WaypointPath(np.vstack([out, [[202.0, 1.5]], back]))
    tracker = ProgressTracker(path)
    tracker.update(np.array([10.0, 2.5]))  # nearer the return leg (~390 m ahead), too far ahead
    assert tracker.farthest_s_m == pytest.approx(10.0)
    tracker.update(np.array([150.0, 0.0]))  # 140 m ahead: fine
    assert tracker.farthest_s_m == pytest.approx(150.0)
    tracker.update(np.array([30.0, 2.9]))  # the return leg there is 225 m ahead: ignored
    assert tracker.farthest_s_m == pytest.approx(150.0)
    tracker.update(np.array([120.0, 3.0]))  # on the return leg, 134 m ahead: progress
    assert tracker.farthest_s_m == pytest.approx(285.0, abs=0.1)
    assert not tracker.finished


def test_progress_finishes_near_the_goal():
    tracker = ProgressTracker(straight(100.0))
    for x in range(0, 100, 5):
        tracker.update(np.array([float(x), 0.0]))
    assert not tracker.finished
    tracker.update(np.array([99.5, 0.2]))
    assert tracker.finished


def test_collisions_are_debounced_over_5_m_and_5_s():
    det = FailureDetector()
    assert det.collision(10.0, 0.0, 0.0, "curb a") is not None
    assert det.collision(12.0, 3.0, 0.0, "building b") is None  # 2 s, 3 m: the same failure
    assert det.collision(14.9, 0.0, 4.9, "tree") is None
    assert det.collision(15.5, 0.0, 0.0, "curb a") is not None  # 5.5 s later: a new one
    assert det.collision(16.0, 6.0, 0.0, "curb a") is not None  # 6 m away: a new one


def test_stuck_and_off_route_count_only_when_chosen():
    paper = FailureDetector()  # collisions alone, as the paper counts
    assert paper.check(30.0, 0, 0, 0.0, 50.0) is None
    det = FailureDetector(
        FailureConfig(
            causes=("collision", "stuck", "off_route"),
            stuck_s=10.0,
            off_route_m=5.0,
            off_route_s=3.0,
        )
    )
    assert det.check(5.0, 0, 0, 0.0, 0.0) is None
    f = det.check(10.0, 1.0, 2.0, 0.05, 0.0)
    assert f is not None and f.cause == "stuck" and (f.x_m, f.y_m) == (1.0, 2.0)
    det.restart(20.0)  # a re-initialization restarts the timers
    assert det.check(25.0, 0, 0, 0.0, 0.0) is None
    assert det.check(26.0, 0, 0, 4.0, 6.0) is None  # off the route since 26 s
    assert det.check(28.0, 0, 0, 4.0, 7.0) is None
    assert det.check(28.5, 0, 0, 4.0, 4.0) is None  # back on it: the clock resets
    assert det.check(29.0, 0, 0, 4.0, 6.0) is None
    f = det.check(32.0, 0, 0, 4.0, 8.0)
    assert f is not None and f.cause == "off_route"


def test_collisions_can_be_left_uncounted():
    det = FailureDetector(FailureConfig(causes=("stuck",)))
    assert det.collision(10.0, 0.0, 0.0, "curb a") is None


def test_bad_config():
    with pytest.raises(ConfigError, match=r"failure\.off_route_m"):
        FailureConfig(off_route_m=0)
    with pytest.raises(
        ConfigError, match=r"unknown failure\.causes 'crash'; valid: collision, off_route, stuck"
    ):
        FailureConfig(causes=("crash",))
