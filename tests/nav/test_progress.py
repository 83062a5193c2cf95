"""Progress along the route: only near it, never jumping far, finished near the goal."""

import numpy as np
import pytest

from tests.nav.paths import straight
from vlocbench.nav import ProgressTracker, WaypointPath


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
