"""Filter consistency (NEES) and answer confidence curves: the numbers, and what they say of the
paper's filter on a real drive."""

import numpy as np
import pytest

from vlocbench.bench import (
    EpisodeConfig,
    LatencyConfig,
    OracleConfig,
    OracleLocalizer,
    plan_town_route,
    run_episode,
)
from vlocbench.bench.consistency import (
    CHI2_3_95,
    confidence_curve,
    consistency,
    ekf_nees,
    nees,
    upper_to_full,
)
from vlocbench.bench.metrics import episode_metrics
from vlocbench.sim import Simulator


def test_nees_of_errors_drawn_from_their_covariance_is_chi_square_3():
    rng = np.random.default_rng(0)
    cov = np.array([[0.5, 0.2, 0.01], [0.2, 0.3, 0.0], [0.01, 0.0, 0.02]])
    errors = rng.multivariate_normal(np.zeros(3), cov, 20000)
    values = nees(errors, np.broadcast_to(cov, (len(errors), 3, 3)))
    c = consistency(values)
    assert c.mean_nees == pytest.approx(3.0, rel=0.03)
    assert c.inside_95 == pytest.approx(0.95, abs=0.01)
    assert c.above == pytest.approx(0.025, abs=0.005) and c.below == pytest.approx(0.025, abs=0.005)
    # a filter that claims a tenth of its variance is overconfident at most steps
    assert consistency(nees(errors, np.broadcast_to(cov / 10, (len(errors), 3, 3)))).above > 0.5
    assert (
        nees(np.ones((1, 3)), np.zeros((1, 3, 3)))[0]
        != nees(np.ones((1, 3)), np.zeros((1, 3, 3)))[0]
    )
    assert np.isnan(consistency(np.array([np.nan])).mean_nees)
    upper = np.array([[1.0, 2, 3, 4, 5, 6]])
    assert (upper_to_full(upper)[0] == [[1, 2, 3], [2, 4, 5], [3, 5, 6]]).all()
    assert pytest.approx(7.8147) == CHI2_3_95


def _records(inliers, right, covariance=None):
    n = len(inliers)
    err = [1.0 if r else 50.0 for r in right]
    return {
        "success": [True] * n + [False],  # and one query not answered
        "x_m": [e for e in err] + [np.nan],
        "y_m": [0.0] * (n + 1),
        "yaw_rad": [0.0] * (n + 1),
        "true_x_m": [0.0] * (n + 1),
        "true_y_m": [0.0] * (n + 1),
        "true_yaw_rad": [0.0] * (n + 1),
        "position_error_3d_m": [*err, np.nan],
        "rotation_error_deg": [0.0] * (n + 1),
        "inliers": [*list(inliers), 0],
        "covariance": (covariance or [()] * n) + [()],
    }


def test_the_confidence_curve_ranks_answers_by_inliers_and_finds_the_threshold():
    # 100 inliers right, 80 right, 60 wrong, 40 right, 20 wrong: 5 answers of 6 queries
    curve = confidence_curve(_records([100, 80, 60, 40, 20], [1, 1, 0, 1, 0]))
    assert curve.by == "inliers" and curve.queries == 6
    assert curve.share == pytest.approx([1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6])
    assert curve.precision == pytest.approx([1, 1, 2 / 3, 3 / 4, 3 / 5])
    assert curve.auc == pytest.approx((1 + 1 + 2 / 3 + 3 / 4 + 3 / 5) / 6)
    # 80 inliers and more keep every answer right: a third of the queries answered
    assert (curve.threshold, curve.share_at_threshold) == (80.0, pytest.approx(2 / 6))
    # ties are answered together
    tied = confidence_curve(_records([50, 50, 10], [1, 0, 1]))
    assert tied.share == pytest.approx([2 / 4, 3 / 4]) and np.isnan(tied.threshold)


def test_own_covariances_rank_answers_when_every_answer_has_one():
    cov = [tuple(np.diag([v, v, 0.01]).ravel()) for v in (4.0, 0.1, 1.0)]
    curve = confidence_curve(_records([10, 20, 30], [0, 1, 1], cov))
    assert curve.by == "covariance" and curve.precision == pytest.approx([1, 1, 2 / 3])


def test_the_papers_filter_is_overconfident_with_late_fixes_and_not_without(small_town):
    """Fixes applied at the current time though taken earlier (the paper's filter) leave the truth
    outside the EKF's ellipse at most steps; on time, the fixed 0.1 covariance is cautious."""
    path = plan_town_route(small_town)
    oracle = OracleLocalizer(OracleConfig(0.1, 1.0))
    with Simulator(small_town) as sim:
        late = run_episode(sim, path, oracle, EpisodeConfig(seed=1))
        on_time = run_episode(
            sim, path, oracle, EpisodeConfig(seed=1, latency=LatencyConfig("none"))
        )
    late_c = consistency(ekf_nees(vars(late.trajectory)))
    on_time_c = consistency(ekf_nees(vars(on_time.trajectory)))
    assert late_c.above > 0.5 and late_c.mean_nees > 10
    assert on_time_c.inside_95 > 0.95 and on_time_c.mean_nees < 3
    extra = episode_metrics(late).extra
    assert extra["ekf_overconfident_share"] == pytest.approx(late_c.above)
    assert extra["answer_inside_95_share"] > 0.9  # the oracle's own covariance is its noise's
