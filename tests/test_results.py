"""Results as DataFrames, checked against the report's own numbers on a real run."""

import numpy as np
import pytest
import yaml

from vlocbench import results
from vlocbench.bench.experiment import load_experiment, plan_from_stored
from vlocbench.bench.store import read_latest_run
from vlocbench.bench.summary import summarize


def test_episodes_as_a_dataframe_give_the_reports_numbers(tiny):
    root, _ = tiny
    out = root / "out"
    df = results.episodes(out)
    stored, rows = read_latest_run(out)
    summary = summarize(plan_from_stored(stored), rows)
    [town] = summary.towns  # as the experiment names it (a YAML path here); df.town: its name
    assert set(df.town) == {summary.town_names[town]} == {"small"}
    assert len(df) == len(rows) and set(df.kind) == {"failure", "recall", "baseline"}
    assert {"illumination.k", "failures_per_km", "recall_0.25m_2deg", "mean_segment_m"} <= set(df)
    assert set(df["illumination.k"].dropna()) == {0, 6}
    failures = df[df.kind != "recall"]
    f = failures.groupby(["method", "setup"]).failures_per_km.mean()
    for (method, setup), value in f.items():
        assert summary.cell(town, method, setup).failure.mean == pytest.approx(value)
    recall = df[df.kind == "recall"].set_index("setup")
    for setup, t1 in recall["recall_0.25m_2deg"].items():
        assert summary.cell(town, "sift", setup).recall[0] == pytest.approx(t1)

    one = recall.iloc[0]
    traj, locs = results.trajectory(out, one.key), results.localizations(out, one.key)
    assert len(locs) == one.queries and locs.success.mean() > 0.5
    assert np.isclose(traj.time_s.diff().median(), 0.05) and {"true_x_m", "ekf_x_m"} <= set(traj)


def test_episodes_of_an_experiment_file_whichever_runs_drove_them(tiny):
    root, _ = tiny
    out = root / "out"
    latest = results.episodes(out)
    whole = results.episodes(out, root / "tiny.yaml")  # the file, as a user names it
    assert sorted(whole.key) == sorted(latest.key)
    noon = results.episodes(out, load_experiment(root / "tiny.yaml").only(setups=["k=0"]))
    assert set(noon.kind) == {"failure", "recall", "baseline"}
    assert set(noon[noon.kind != "baseline"]["illumination.k"]) == {0}
    assert len(noon) < len(whole)


def test_a_sweep_grown_by_a_key_names_the_stored_episodes_by_its_setups(tiny, tmp_path):
    root, _ = tiny
    out = root / "out"
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    spec["sweep"]["episode.ekf.late_measurements"] = ["current", "replay"]
    (tmp_path / "tiny_grown.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    before = results.episodes(out, root / "tiny.yaml").set_index("key")
    grown = results.episodes(out, tmp_path / "tiny_grown.yaml").set_index("key")
    # the stored drives are the grown plan's "current" ones (pure keys), named by its setups
    assert sorted(grown.index) == sorted(before.index)
    drives = grown[grown.kind != "baseline"]
    assert set(drives["episode.ekf.late_measurements"]) == {"current"}
    assert (drives["illumination.k"] == before.loc[drives.index, "illumination.k"]).all()
    assert set(drives.setup) == {
        f"illumination.k={k}, episode.ekf.late_measurements=current" for k in (0, 6)
    }
    assert grown.loc[drives.index, "failures_per_km"].equals(
        before.loc[drives.index, "failures_per_km"]
    )
