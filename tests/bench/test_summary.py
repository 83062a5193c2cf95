"""Summaries: stored episodes found under the setups of the plan that reads them, also those of an
earlier run of another sweep or of an older EPISODE_VERSION."""

from tests.bench.fakes import ILL_SPEC, run_fake, run_fake_plans
from vlocbench.bench.executors import execute
from vlocbench.bench.experiment import load_experiment, plan_from_stored
from vlocbench.bench.store import ResultStore, read_episodes, read_latest_run, run_hash
from vlocbench.bench.summary import summarize
from vlocbench.config import to_dict


def test_a_grouped_sweep_whose_keys_are_not_sorted_reports_every_cell(tmp_path):
    """The store keeps JSON with sorted keys; the setups it gives back must be the same setups."""
    levels = [{"fog_visual_range_m": v, "rain": 0.8, "overcast": 0.8} for v in (90, 30)]
    spec = load_experiment(
        {
            "name": "wx",
            "towns": ["town10"],
            "methods": ["sift"],
            "repetitions": 1,
            "sweep": {"weather": levels},
        }
    )
    tasks = spec.tasks()
    with ResultStore(tmp_path, "wx") as store:
        store.start_run(run_hash(t.key for t in tasks), to_dict(spec), [t.key for t in tasks])
        execute(tasks, store, workers=1, runner=run_fake, progress=False)
    stored, rows = read_latest_run(tmp_path)
    summary = summarize(plan_from_stored(stored), rows)
    labels = [s.label for s in summary.setups]
    assert labels == [
        "weather(fog_visual_range_m=90, overcast=0.8, rain=0.8)",
        "weather(fog_visual_range_m=30, overcast=0.8, rain=0.8)",
    ]
    for label in labels:
        for method in ("sift", "odometry"):
            cell = summary.cell("town10", method, label)
            assert cell is not None and cell.failure is not None, (method, label)
        assert summary.cell("town10", "sift", label).recall is not None


def test_episodes_another_sweep_ran_first_count_under_this_plans_setups(tmp_path):
    """The reduced sweep's k = 0 episodes were first run as a one-level sweep ("default")."""
    first = load_experiment({**ILL_SPEC, "sweep": {"illumination.k": [0]}})
    second = load_experiment({**ILL_SPEC, "sweep": {"illumination.k": [0, 6]}})
    run_fake_plans(tmp_path, first, second)
    stored, rows = read_latest_run(tmp_path)
    assert {r.setup for r in rows} == {"default", "illumination.k=6"}  # as each run stored them
    summary = summarize(plan_from_stored(stored), rows)
    for label in ("illumination.k=0", "illumination.k=6"):
        cell = summary.cell("town10", "sift", label)
        assert cell is not None and cell.failure is not None and cell.recall is not None, label


def test_an_old_runs_report_shows_its_episodes_where_they_were_stored(tmp_path, monkeypatch):
    """A run stored by an earlier EPISODE_VERSION: its keys are none of the plan's now, yet its
    report shows every cell, the baseline under every setup it served."""
    import vlocbench.bench.experiment as experiment

    run_fake_plans(tmp_path, load_experiment({**ILL_SPEC, "sweep": {"illumination.k": [0, 6]}}))
    monkeypatch.setattr(experiment, "EPISODE_VERSION", experiment.EPISODE_VERSION + 1)
    stored, rows = read_latest_run(tmp_path)
    plan = plan_from_stored(stored)
    assert not {t.key for t in plan.tasks()} & {r.key for r in rows}
    summary = summarize(plan, rows)
    for label in ("illumination.k=0", "illumination.k=6"):
        for method in ("sift", "odometry"):
            cell = summary.cell("town10", method, label)
            assert cell is not None and cell.failure is not None, (method, label)


def test_a_rerun_under_a_new_episode_version_reports_only_its_own_episodes(tmp_path, monkeypatch):
    """The same experiment file run again after EPISODE_VERSION changed: the old episodes stay in
    the store, and the latest run's report holds the new ones only, never both."""
    import vlocbench.bench.experiment as experiment

    spec = {**ILL_SPEC, "sweep": {"illumination.k": [0, 6]}}
    run_fake_plans(tmp_path, load_experiment(spec))
    monkeypatch.setattr(experiment, "EPISODE_VERSION", experiment.EPISODE_VERSION + 1)
    plan = load_experiment(spec)
    run_fake_plans(tmp_path, plan)
    stored, rows = read_latest_run(tmp_path)
    keys = {t.key for t in plan.tasks()}
    assert {r.key for r in rows} == keys and len(read_episodes(tmp_path)) == 2 * len(keys)
    summary = summarize(plan_from_stored(stored), rows)
    assert summary.episodes == summary.planned == len(keys)


def test_a_run_in_parts_reports_the_towns_and_methods_it_has_and_names_the_rest(tmp_path):
    """`vlocbench run --towns town10 --methods sift` into a two-town, two-method experiment: the
    summary holds town10 and sift, and says that town01, orb-teblid and the odometry line have none."""
    from vlocbench.bench.report import not_stored_line
    from vlocbench.bench.report.page import write_page

    spec = load_experiment(
        {**ILL_SPEC, "towns": ["town01", "town10"], "methods": ["sift", "orb-teblid"]}
    )
    run_fake_plans(tmp_path, spec)
    _, rows = read_latest_run(tmp_path)
    part = [r for r in rows if r.town == "town10" and r.method == "sift"]
    assert part and len(part) < len(rows)
    summary = summarize(spec, part)
    assert summary.towns == ("town10",) and summary.methods == ("sift",)
    assert summary.towns_not_stored == ("town01",)
    assert summary.methods_not_stored == ("orb-teblid", "odometry")
    line = not_stored_line(summary)
    assert line.startswith("nothing stored yet for town01, orb-teblid, odometry only")
    page = write_page(summary, part, [], [], False, tmp_path).read_text()
    assert "towns: town10 (nothing stored yet for town01" in page and "methods: sift;" in page
    whole = summarize(spec, rows)
    assert whole.towns == ("town01", "town10") and not not_stored_line(whole)


def test_a_cells_repetitions_are_read_in_repetition_order_whatever_the_row_order(tmp_path):
    """The store gives rows by key (a hash); F's repetitions and interval must not follow it."""
    run_fake_plans(tmp_path, load_experiment({**ILL_SPEC, "repetitions": 4}))
    stored, rows = read_latest_run(tmp_path)
    plan = plan_from_stored(stored)
    cells = [
        summarize(plan, order).cell("town10", "sift", "default")
        for order in (rows, rows[::-1], sorted(rows, key=lambda r: -r.repetition))
    ]
    assert all(c is not None and c.failure == cells[0].failure for c in cells)
    per_rep = cells[0].failure.per_repetition
    assert [v > 0 for v in per_rep] == [False, True, False, True]  # fakes fail on odd ones
