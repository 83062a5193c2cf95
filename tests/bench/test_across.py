"""Results across towns: the mean over towns with its two intervals, and whether towns rank the
methods alike (Kendall's tau-b)."""

import dataclasses

import pytest

from tests.bench.fakes import ILL_SPEC, run_fake_plans
from vlocbench.bench.across import across_towns, kendall_tau_b, rank_agreement
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.metrics import failure_rate
from vlocbench.bench.report import report_tables
from vlocbench.bench.store import read_episodes
from vlocbench.bench.summary import summarize


def test_kendall_tau_b_counts_ties_as_tau_b_does():
    assert kendall_tau_b([1, 2, 3], [10, 20, 30]) == 1.0
    assert kendall_tau_b([1, 2, 3], [3, 2, 1]) == -1.0
    # 5 concordant pairs, one tied in x only: 5 / sqrt(6 * 5)
    assert kendall_tau_b([1, 2, 2, 3], [1, 3, 2, 4]) == pytest.approx(5 / 30**0.5)
    assert kendall_tau_b([1, 1, 1], [1, 2, 3]) != kendall_tau_b([1, 1, 1], [1, 2, 3])  # NaN


# per town: each method's failures/km in its two repetitions
TOWN_F = {
    "town10": {"sift": [0, 0], "sift-gem": [2, 4], "odometry": [10, 12]},
    "gen-city-1-0": {"sift": [0, 0], "sift-gem": [3, 3], "odometry": [12, 10]},
    "gen-city-1-1": {"sift": [6, 6], "sift-gem": [1, 1], "odometry": [10, 10]},
}


@pytest.fixture()
def three_towns(tmp_path):
    spec = {**ILL_SPEC, "towns": list(TOWN_F), "methods": ["sift", "sift-gem"]}
    plan = load_experiment({**spec, "repetitions": 2, "baseline_repetitions": 2})
    run_fake_plans(tmp_path, plan)
    summary = summarize(plan, read_episodes(tmp_path))
    cells = {
        key: dataclasses.replace(c, failure=failure_rate(TOWN_F[key[0]][key[1]]))
        for key, c in summary.cells.items()
    }
    return dataclasses.replace(summary, cells=cells)


def test_across_towns_means_and_intervals(three_towns):
    rows = {r.method: r for r in across_towns(three_towns)}
    assert set(rows) == {"sift", "sift-gem", "odometry"}
    vlad = rows["sift"]
    assert vlad.towns == 3 and vlad.failure_mean == pytest.approx(2.0)
    # drawing towns: anywhere from all-zero towns to the one at 6; drawing repetitions: none vary
    assert vlad.failure_towns[0] == 0.0 and vlad.failure_towns[1] == pytest.approx(6.0)
    assert vlad.failure_repetitions == pytest.approx((2.0, 2.0))
    odo = rows["odometry"]
    assert odo.failure_repetitions[0] < odo.failure_mean < odo.failure_repetitions[1]
    assert 0 < vlad.recall_t1 <= 1 and vlad.recall_towns[0] <= vlad.recall_t1


def test_a_town_that_reverses_two_methods_breaks_the_agreement(three_towns):
    [agreement] = rank_agreement(three_towns, across_towns(three_towns))
    assert agreement.order == ("sift", "sift-gem", "odometry")  # means 2.0, 2.33, 10.67
    assert agreement.tau_by_town["town10"] == 1.0
    assert agreement.tau_by_town["gen-city-1-1"] == pytest.approx(1 / 3)
    assert not agreement.same_everywhere and agreement.tau_min == pytest.approx(1 / 3)
    captions = [c for c, _ in report_tables(three_towns)]
    assert any(c.startswith("do the 3 towns rank the methods alike") for c in captions)
    [(_, (_, [row]))] = [(c, t) for c, t in report_tables(three_towns) if c.startswith("do the")]
    assert row[1] == "sift < sift-gem < odometry only" and row[3] == "no: gen-city-1-1"
    tied = dataclasses.replace(agreement, means=(2.0, 2.0, 10.0))
    assert tied.ranking() == "sift = sift-gem < odometry"
