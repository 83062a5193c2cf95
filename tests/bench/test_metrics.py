import numpy as np

from tests.bench.fakes import synthetic_result
from vlocbench.bench.metrics import episode_metrics, failure_rate, fragmentation, recall


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
    assert m.recall_ekf == (1.0, 1.0, 1.0, 1.0)
    assert m.lock_losses_per_km == 30.0
    assert m.queries == 4 and m.ct_mean_s == 0.05
