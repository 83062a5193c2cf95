"""An episode as a rerun recording."""

import pytest
import yaml

from vlocbench.bench.store import ResultStore


def test_an_episode_as_a_rerun_recording_reads_back(tiny, tmp_path, capsys):
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    from vlocbench.bench.store import read_episode_table
    from vlocbench.cli import main

    root, _ = tiny
    out = root / "out"
    path = tmp_path / "drive.rrd"
    args = ["view", str(out), "--setup", "k=6", "--method", "sift", "--images"]
    assert main([*args, "--out", str(path)]) == 0
    assert "failure drive" in capsys.readouterr().out  # failure drives first
    rows: dict[str, int] = {}
    for chunk in RrdReader(path).stream().collect().stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    with ResultStore(out, "tiny") as store:
        [row] = [r for r in store.rows() if r.kind == "failure" and r.setup.endswith("k=6")]
    locs = read_episode_table(out, row.key, "localizations")
    steps = len(read_episode_table(out, row.key, "trajectory")["time_s"])
    assert rows["/localization/log"] == len(locs["time_s"])  # every query, answered or not
    assert rows["/localization/camera"] == int(locs["success"].sum())  # a frustum per answer
    assert rows["/localization/camera/image"] == len(locs["time_s"])
    assert rows["/retrieved/0"] == len(locs["time_s"])
    assert rows["/truth"] == rows["/ekf"] == steps
    assert {"/town/buildings", "/route", "/truth/path", "/ekf/path"} <= set(rows)
    assert main(["view", str(out), "--method", "nope"]) == 1
    assert "there are: " in capsys.readouterr().err
    assert main(["view", str(out), "--episode", row.key]) == 0  # to OUTPUT/view/KEY.rrd
    from vlocbench.bench.report import write_report

    page = write_report(out, examples=False).html.read_text()
    assert f'<a href="../view/{row.key}.rrd">' in page and "failure drive, small, sift" in page


def test_episodes_of_earlier_runs_by_key_or_by_experiment(tiny, tmp_path):
    """After a run of one part of the experiment (its latest run), an episode of another part is
    found by its key, and by setup and method once the experiment is named."""
    import shutil

    from vlocbench.bench.experiment import load_experiment
    from vlocbench.bench.export import export_run
    from vlocbench.bench.runner import run_experiment
    from vlocbench.bench.store import StoreError
    from vlocbench.bench.view import choose_episode

    root, _ = tiny
    out = tmp_path / "out"
    shutil.copytree(root / "out", out)
    plan = load_experiment(root / "tiny.yaml").with_output(out)
    run_experiment(plan.only(setups=["k=0"]), progress=False)  # all done: a run of the part
    night = choose_episode(out, setup="k=6", method="sift", experiment=root / "tiny.yaml")
    assert night.setup.endswith("k=6") and night.kind == "failure"
    assert choose_episode(out, key=night.key[:12]).key == night.key
    # a sweep grown by a key names the same episode by one key's level, or by its whole label
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    spec["sweep"]["episode.ekf.late_measurements"] = ["current", "replay"]
    grown = tmp_path / "grown.yaml"
    grown.write_text(yaml.safe_dump(spec, sort_keys=False))
    for name in ("k=6", "k=6, episode.ekf.late_measurements=current"):
        assert choose_episode(out, setup=name, method="sift", experiment=grown).key == night.key
    with pytest.raises(StoreError, match=r"there are: illumination\.k=0"):
        choose_episode(out, setup="k=6", method="sift")  # not in the latest run
    part = {p.parent.name for p in export_run(out, "tum")}
    whole = {p.parent.name for p in export_run(out, "tum", plan)}
    assert night.key in whole - part


def test_an_episode_chosen_by_town_kind_repetition_or_as_the_first_that_failed(tmp_path, capsys):
    """Fake drives fail on odd repetitions; two towns, so the town must be named to be sure."""
    from tests.bench.fakes import ILL_SPEC, run_fake_plans
    from vlocbench.bench.experiment import load_experiment
    from vlocbench.bench.records import EPISODE_KINDS
    from vlocbench.bench.store import StoreError
    from vlocbench.bench.view import choose_episode
    from vlocbench.cli import main

    spec = {**ILL_SPEC, "towns": ["town10", "town01"], "repetitions": 4}
    run_fake_plans(tmp_path, load_experiment(spec))
    first = choose_episode(tmp_path, method="sift", town="town01")
    assert (first.town, first.kind, first.repetition) == ("town01", "failure", 0)
    crashed = choose_episode(tmp_path, method="sift", town="town01", failed=True)
    assert crashed.repetition == 1 and crashed.metrics.failures == 1
    third = choose_episode(tmp_path, town="town10", method="sift", repetition=2)
    assert (third.town, third.repetition) == ("town10", 2)
    assert choose_episode(tmp_path, town="town10", kind="recall").kind == "recall"
    with pytest.raises(StoreError, match=r"none of the 1 finished episodes of .* failed"):
        choose_episode(tmp_path, town="town10", kind="recall", failed=True)
    with pytest.raises(StoreError, match="there are: town01: default / odometry"):
        choose_episode(tmp_path, town="town02")
    with pytest.raises(SystemExit) as stop:
        main(["view", str(tmp_path), "--repetition", "-1"])
    assert stop.value.code == 2 and "must be at least 0" in capsys.readouterr().err
    for kind in EPISODE_KINDS:  # the command line's choices are the episode kinds
        assert main(["view", str(tmp_path), "--kind", kind, "--town", "town02"]) == 1
        assert f"kind '{kind}'; there are: " in capsys.readouterr().err
