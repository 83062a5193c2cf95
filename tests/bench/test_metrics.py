import dataclasses
import json

import numpy as np
import pytest

from tests.bench.fakes import synthetic_result
from vlocbench.bench.metrics import (
    EpisodeMetrics,
    Metric,
    confident_wrong,
    drift_segments,
    episode_metrics,
    failure_rate,
    failure_rate_by_cause,
    fragmentation,
    place_recall,
    pooled_drift,
    recall,
)
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.geometry import make_pose, planar_pose, pose_error, rot_x


def test_recall_counts_failed_localizations_as_misses():
    pos = np.array([0.1, 0.3, 4.0, np.nan, 0.2])
    yaw = np.array([1.0, 1.0, 1.0, np.nan, 3.0])
    assert recall(pos, yaw) == (0.2, 0.6, 0.8, 0.8)
    assert all(np.isnan(v) for v in recall(np.array([]), np.array([])))


def test_failure_rate_bootstrap_interval():
    f = failure_rate([10.0, 20.0, 30.0, 0.0, 40.0])
    assert f.mean == 20.0 and f.repetitions == 5
    assert 0.0 <= f.low < f.mean < f.high <= 40.0
    assert failure_rate([10.0, 20.0, 30.0, 0.0, 40.0]) == f  # seeded
    uneven = [0.1, 3.7, 0.0, 12.9, 0.4]
    a, b = failure_rate(uneven), failure_rate(uneven[::-1])
    assert (a.low, a.high) == (b.low, b.high)  # the values decide, not their order
    assert b.per_repetition == tuple(uneven[::-1])
    one = failure_rate([7.0])
    assert (one.low, one.mean, one.high) == (7.0, 7.0, 7.0)
    assert np.isnan(failure_rate([]).mean)


def test_fragmentation_finds_hotspots():
    scattered = fragmentation([10.0, 300.0, 600.0, 900.0])
    assert scattered.places == 4 and scattered.top_share == 0.25
    hotspot = fragmentation([410.0, 412.0, 420.0, 900.0])
    assert hotspot.places == 2 and hotspot.top_share == 0.75 and hotspot.worst_s_m == 400.0
    assert fragmentation([]).failures == 0


def test_episode_metrics():
    m = episode_metrics(synthetic_result(failures=2, queries=4, lock_losses=3))
    assert m.failures == 2 and m.failures_per_km == 20.0
    assert m.failure_sites_s_m == (20.0, 40.0) and m.failure_sites_xy == ((20.0, 0.0), (40.0, 0.0))
    assert m.recall == (1.0, 1.0, 1.0, 1.0)  # 0.1 m and 0.5 deg off
    assert m.recall_planar == (1.0, 1.0, 1.0, 1.0) and m.confident_wrong == 0.0
    assert m.recall_ekf == (1.0, 1.0, 1.0, 1.0)
    assert m.lock_losses_per_km == 30.0
    assert m.queries == 4 and m.ct_mean_s == 0.05


def test_six_dof_errors_and_confident_wrong_answers():
    truth = planar_pose(10.0, 5.0, 0.3)
    tilted = truth @ make_pose(rot_x(np.radians(3.0)), np.array([0.0, 0.0, 0.2]))
    pos, rot = pose_error(truth, tilted)
    assert pos == pytest.approx(0.2) and rot == pytest.approx(3.0)
    # planar errors would call this pose perfect; 6-DoF recall does not at (0.25 m, 2 deg)
    assert recall(np.array([pos]), np.array([rot]))[:2] == (0.0, 1.0)
    # thresholds are inclusive
    assert recall(np.array([0.25, 0.5]), np.array([2.0, 5.0]))[:2] == (0.5, 1.0)
    wrong = confident_wrong(np.array([0.1, 6.0, 0.2, np.nan]), np.array([1.0, 1.0, 11.0, np.nan]))
    assert wrong == 0.5  # two of four answered beyond (5 m, 10 deg); the failure is not wrong
    assert np.isnan(confident_wrong(np.array([]), np.array([])))


def test_wrong_answers_the_ekf_took_and_those_the_retrieval_caused():
    """Of 10 answers on 100 m: 4 wrong (one by rotation alone), 2 of them fused; 3 of the wrong
    had a retrieval, one of those with an image within 10 m."""
    result = synthetic_result(failures=0, queries=10)
    wrong = {
        0: dict(position_error_3d_m=30.0, fused=True, retrieval_distances_m=(40.0, 12.0)),
        1: dict(rotation_error_deg=15.0, fused=False, retrieval_distances_m=(30.0, 3.0)),
        2: dict(position_error_3d_m=6.0, fused=True),
        3: dict(position_error_3d_m=80.0, fused=False, retrieval_distances_m=(90.0,)),
        4: dict(position_error_3d_m=4.0, retrieval_distances_m=(50.0,)),  # not beyond 5 m
        5: dict(success=False, position_error_3d_m=float("nan"), fused=None),
    }
    locs = tuple(
        dataclasses.replace(x, **wrong.get(k, {})) for k, x in enumerate(result.localizations)
    )
    m = episode_metrics(dataclasses.replace(result, localizations=locs))
    assert m.extra["wrong_fused_per_km"] == pytest.approx(20.0)  # 2 over 0.1 km
    assert m.extra["wrong_place_missed_share"] == pytest.approx(2 / 3)
    right = episode_metrics(synthetic_result(failures=0, queries=10))
    assert right.extra["wrong_fused_per_km"] == 0.0
    assert np.isnan(right.extra["wrong_place_missed_share"])


def test_failure_rate_by_cause_adds_up_to_f():
    causes = [("collision", "collision"), ("collision", "timeout"), ()]
    covered = [500.0, 250.0, 500.0]
    by_cause = failure_rate_by_cause(causes, covered)
    assert by_cause == pytest.approx({"collision": (4 + 4 + 0) / 3, "timeout": 4 / 3})
    assert sum(by_cause.values()) == pytest.approx(np.mean([4.0, 8.0, 0.0]))


def test_drift_at_the_end_of_each_failure_free_stretch():
    r = synthetic_result(failures=0)  # 100 m, the EKF 0.1 m ahead all along
    segments = drift_segments(r)
    assert len(segments) == 1
    driven, pos, yaw = segments[0]
    assert driven == pytest.approx(100.0) and pos == pytest.approx(0.1) and yaw == 0.0
    d = pooled_drift([(100.0, 8.5, 40.0), (50.0, 2.0, 10.0)])
    assert d.position_percent == pytest.approx((8.5 + 4.0) / 2)
    assert d.yaw_deg_per_m == pytest.approx(0.3) and d.segments == 2
    # a failure at 5 s splits the drive: 20 m, then 80 m (to within a 2 m sample)
    two = drift_segments(synthetic_result(failures=1))
    assert [s[0] for s in two] == pytest.approx([20.0, 80.0], abs=2.1)
    # the paper's rule: every stretch longer than 0.3 m counts (a 6 m one between failures at
    # 5 s and 7 s too); one of 0.3 m or less is a double re-initialization and is left out
    r = synthetic_result(failures=2)
    r = dataclasses.replace(
        r,
        reinitializations=(
            r.reinitializations[0],
            dataclasses.replace(r.reinitializations[1], time_s=7.0),
        ),
    )
    assert [s[0] for s in drift_segments(r)] == pytest.approx([20.0, 6.1, 72.0], abs=2.1)
    tr = r.trajectory
    standing = np.where((tr.time_s > 5.0) & (tr.time_s < 7.0), 20.25, tr.true_x_m)
    r = dataclasses.replace(r, trajectory=dataclasses.replace(tr, true_x_m=standing))
    assert len(drift_segments(r)) == 2


def test_a_timed_out_episode_counts_a_failure_over_the_route_it_covered():
    done = synthetic_result(failures=1)
    late = dataclasses.replace(done, completed=False, route_covered_m=40.0, timeout_is_failure=True)
    assert late.failure_causes == ("collision", "timeout")
    assert late.failures == 2 and late.failures_per_km == pytest.approx(2 / 0.04)
    m = episode_metrics(late)
    assert not m.completed and m.failure_causes[-1] == "timeout" and m.route_covered_m == 40.0
    uncounted = dataclasses.replace(late, timeout_is_failure=False)  # the paper's harness
    assert uncounted.failure_causes == ("collision",)
    assert uncounted.failures_per_km == pytest.approx(1 / 0.04)


def test_place_recall_counts_a_retrieved_image_within_the_distance_among_the_first_n():
    distances = [
        [3.0, 30.0, 30.0, 30.0, 30.0, 30.0, 30.0, 30.0, 30.0, 30.0],  # right at once
        [30.0, 30.0, 8.0, 30.0, 30.0, 30.0, 30.0, 30.0, 30.0, 2.0],  # 8 m third, 2 m tenth
        [40.0] * 10,  # never
        [],  # no ranking (not a retrieval method): not counted
    ]
    r = place_recall(distances)  # N-major: @1 (5, 10, 25 m), @5 (...), @10 (...)
    assert r == pytest.approx([1 / 3, 1 / 3, 1 / 3, 1 / 3, 2 / 3, 2 / 3, 2 / 3, 2 / 3, 2 / 3])
    assert all(np.isnan(place_recall([[], []])))


def test_stored_metrics_read_back_typed_and_old_rows_fill_in():
    m = episode_metrics(synthetic_result(2))
    stored = json.loads(json.dumps(dataclasses.asdict(m)))  # as the store keeps them
    back = EpisodeMetrics.from_stored(stored)
    assert json.dumps(dataclasses.asdict(back)) == json.dumps(dataclasses.asdict(m))  # NaN too
    assert isinstance(back.failure_sites_xy[0], tuple) and back.failure_causes == ("collision",) * 2
    # a row of an earlier version: no place recall yet, and a metric stored as a field then
    old = {k: v for k, v in stored.items() if k not in ("place_recall", "extra")}
    old["mean_segment_m"] = 33.0
    back = EpisodeMetrics.from_stored(old)
    assert back.place_recall == () and back.extra == {"mean_segment_m": 33.0}


@pytest.fixture
def declared():
    """The declared metrics as they were before the test."""
    from vlocbench.bench.metrics import METRICS

    before = dict(METRICS)
    yield
    METRICS.clear()
    METRICS.update(before)


def test_a_metric_is_one_declaration(tmp_path, declared):
    """Declared once, a metric is computed for every stored episode, combined per cell as it
    says, and shown in the report's table of declared metrics."""
    from tests.bench.fakes import ILL_SPEC, run_fake_plans
    from vlocbench.bench import metrics
    from vlocbench.bench.experiment import load_experiment
    from vlocbench.bench.report import write_report

    metrics.declare_metric(
        Metric(
            name="reinits_x10",
            episode=lambda r: 10.0 * r.failures,
            header="10 x failures",
            combine=max,
            digits=0,
        )
    )
    with pytest.raises(ConfigError, match="declared already"):
        metrics.declare_metric(Metric(name="queries", episode=len, header="q"))
    with pytest.raises(UnknownNameError, match=r"metric\.kinds"):
        metrics.declare_metric(Metric(name="x", episode=len, header="x", kinds=("ground",)))
    run_fake_plans(tmp_path, load_experiment({**ILL_SPEC, "sweep": {"illumination.k": [0, 6]}}))
    files = write_report(tmp_path, examples=False)
    # the fakes: failure drives of repetition 0 fail 0 times, odometry drives 3 times
    summary = files.summary
    assert summary.cell("town10", "sift", "illumination.k=6").extra["reinits_x10"] == 0.0
    assert summary.cell("town10", "odometry", "illumination.k=6").extra["reinits_x10"] == 30.0
    md = files.markdown.read_text()
    assert "town10: declared metrics" in md and "| 10 x failures |" in md
    [row] = [r for r in md.splitlines() if r.startswith("| odometry only | all | 100 | 0.10 |")]
    assert row.endswith("| 30 |")  # after the NEES columns (the fakes record a covariance)
