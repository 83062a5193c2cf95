"""Failures: collisions debounced, the optional causes counted only when chosen."""

import pytest

from vlocbench.errors import ConfigError
from vlocbench.nav import FailureConfig, FailureDetector


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
