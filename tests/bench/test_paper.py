import numpy as np
import pytest

from tests.bench.fakes import run_fake
from vlocbench.bench.executors import execute
from vlocbench.bench.experiment import load_experiment, plan_from_stored
from vlocbench.bench.paper import paper_results, shape, spearman
from vlocbench.bench.report.comparison import paper_comparison_tables
from vlocbench.bench.store import ResultStore, read_latest_run, run_hash
from vlocbench.bench.summary import summarize
from vlocbench.config import to_dict


def test_the_paper_tables_ship_with_the_package():
    p = paper_results()
    assert "WACV 2023" in p.citation and len(p.methods) == 8
    assert p.odometry_failure_rate == {"town01": 17.9, "town10": 9.8}
    ill = p.tables["illumination"]
    assert ill.levels == tuple(range(11))
    assert ill.failure_rate["town01"]["AP-GeM + SIFT"][6] == 11.6
    assert ill.failure_rate["town10"]["NetVLAD + SuperPoint"][-1] == 8.5
    assert ill.recall_levels == (0, 2, 4, 6, 8, 10)
    assert ill.recall_t1["town10"]["AP-GeM + SIFT"] == (95.2, 89.5, 87.1, 76.6, 12.5, 0.0)
    assert p.tables["viewpoint"].levels[3] == (5, 27.5)
    assert p.tables["weather"].failure_rate["town10"]["NetVLAD + SIFT"] == (7.6, 25.9, 29.5, 25.9)
    assert p.computation_time_ms["NetVLAD + SIFT"] == 134


def test_spearman_and_shape_measures():
    assert spearman([0, 1, 2, 3], [1, 5, 7, 30]) == pytest.approx(1.0)
    assert spearman([0, 1, 2, 3], [4, 3, 2, 1]) == pytest.approx(-1.0)
    assert spearman([0, 1, 2], [1, 1, 2]) == pytest.approx(np.sqrt(3) / 2)  # tied ranks
    assert np.isnan(spearman([0, 1, 2], [5, 5, 5]))
    # the paper's SIFT in Town01: F rises with k, passes the odometry line at k = 7, and above
    # the line the best recall among the levels where both are known is 19.2 % (k = 8)
    p = paper_results().tables["illumination"]
    f = p.failure_rate["town01"]["AP-GeM + SIFT"]
    t1 = dict(zip(p.recall_levels, p.recall_t1["town01"]["AP-GeM + SIFT"]))
    s = shape(f, 17.9, None, [t1.get(k, np.nan) for k in p.levels])
    assert s.f_easiest == 0.0 and s.rank_correlation > 0.8
    assert s.odometry_level == 7 and s.worse_than_odometry_below_t1 == 19.2
    never = shape([0.0, 1.0, 2.0], 17.9)
    assert never.odometry_level is None and np.isnan(never.worse_than_odometry_below_t1)


def test_a_run_is_reported_beside_the_paper(tmp_path):
    spec = load_experiment(
        {
            "name": "ill",
            "towns": ["town10"],
            "methods": ["sift"],
            "repetitions": 2,
            "sweep": {"illumination.k": [0, 6, 8]},
        }
    )
    tasks = spec.tasks()
    with ResultStore(tmp_path, "ill") as store:
        store.start_run(run_hash(t.key for t in tasks), to_dict(spec), [t.key for t in tasks])
        execute(tasks, store, workers=1, runner=run_fake, progress=False)
    stored, rows = read_latest_run(tmp_path)
    tables = dict(paper_comparison_tables(summarize(plan_from_stored(stored), rows)))
    f_caption = next(c for c in tables if "beside the paper's (Suomela" in c)
    header, body = tables[f_caption]
    assert header == ["source", "method", "0", "6", "8"]
    assert ["paper", "AP-GeM + SIFT", "0.0", "10.3", "25.0"] in body
    assert body[0][:2] == ["vlocbench", "sift"] and body[1][1] == "odometry only"
    recall = next(t for c, t in tables.items() if "T1 recall" in c)
    assert recall[0] == ["source", "method", "0", "6", "8"]
    assert ["paper", "NetVLAD + SIFT", "96.4", "75.4", "12.9"] in recall[1]
    shapes = next(t for c, t in tables.items() if "shape of F" in c)
    assert shapes[1][0][:2] == ["vlocbench", "sift"] and len(shapes[1]) == 1 + 8
    # one level: beside the paper's at that level, without shapes
    k0 = load_experiment(
        {"name": "ill", "towns": ["town10"], "methods": ["sift"], "sweep": {"illumination.k": [0]}}
    )
    one = dict(paper_comparison_tables(summarize(k0, [])))
    assert [t[0] for c, t in one.items() if "F (failures/km)" in c] == [["source", "method", "0"]]
    assert not any("shape of F" in c for c in one)
    # a sweep the paper has no table for gets no comparison
    season = load_experiment(
        {
            "name": "s",
            "towns": ["town10"],
            "methods": ["sift"],
            "sweep": {"season": ["summer", "winter"]},
        }
    )
    assert paper_comparison_tables(summarize(season, [])) == []
