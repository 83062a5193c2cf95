"""A real experiment end to end (gallery, map, episodes, store), resumed, and the gallery cache check."""

import json
import sqlite3
from pathlib import Path

import pytest

from vlocbench.bench import cache
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.platform import current_platform, read_platform_file
from vlocbench.bench.runner import run_experiment
from vlocbench.bench.store import DB_FILE, ResultStore, read_platforms


def test_experiment_runs_end_to_end_and_resumes(tiny):
    root, summary = tiny
    assert (summary.total, summary.finished, summary.errors) == (
        5,
        5,
        0,
    )  # 2 x (recall + failure) + 1 baseline
    assert list((root / "cache" / "galleries").iterdir()) and list(
        (root / "cache" / "maps").iterdir()
    )
    with ResultStore(root / "out", "tiny") as store:
        rows = store.rows()
    # each episode names the platform it ran on: this machine's, as this process computes it
    # (the workers' one thread each changes no digest), its record stored once
    here = current_platform()
    assert {r.platform for r in rows} == {here.id}
    assert read_platforms(root / "out") == {here.id: json.loads(json.dumps(here.to_dict()))}
    # and the gallery and the map, each in its folder: made here too
    [gallery] = (root / "cache" / "galleries").iterdir()
    [map_dir] = (root / "cache" / "maps").glob("*/*")
    assert read_platform_file(gallery)["made_on"]["id"] == here.id
    made = read_platform_file(map_dir)
    assert made["made_on"]["id"] == made["gallery_made_on"]["id"] == here.id
    assert made["gallery"] == gallery.name
    assert {e.platform for e in cache.entries(root / "cache")} == {here.id}  # as listed
    recall = [r for r in rows if r.kind == "recall"]
    assert len(recall) == 2 and all(r.metrics.queries > 10 for r in recall)
    assert all(r.metrics.recall[3] > 0.5 for r in recall)  # it localizes on its own map
    assert all(r.metrics.place_recall[-1] > 0.9 for r in recall)  # Recall@10 within 25 m
    assert {r.config["setup"]["conditions"]["illumination"]["k"] for r in recall} == {0.0, 6.0}
    again = run_experiment(load_experiment(root / "tiny.yaml"), progress=False)
    assert (again.skipped, again.finished) == (5, 0)
    # every stored row is strict JSON: SQLite's JSON functions read all of them (the baseline's
    # metrics have no queries, hence NaN recall and computation time, stored as null)
    with sqlite3.connect(root / "out" / DB_FILE) as db:
        valid = db.execute(
            "SELECT count(*), sum(json_valid(config) AND json_valid(metrics)),"
            " sum(json_extract(metrics, '$.ct_mean_s') IS NULL) FROM episodes"
        ).fetchone()
        assert valid == (5, 5, 1)
        assert db.execute("SELECT count(*) FROM runs WHERE json_valid(spec)").fetchone() == (1,)
        kinds = db.execute(
            "SELECT json_extract(config, '$.kind'), json_extract(metrics, '$.failures_per_km') "
            "FROM episodes ORDER BY key"
        ).fetchall()
        assert {k for k, _ in kinds} == {"recall", "failure", "baseline"}


def test_episodes_driven_on_another_capture_of_the_gallery_are_not_mixed_in(tiny, tmp_path):
    """Keys name the gallery by what makes it; its content is checked: a store whose episodes
    were driven on a gallery with another index stops the run before any episode."""
    import shutil

    from vlocbench.bench.store import StoreError

    root, _ = tiny
    out = tmp_path / "out"
    shutil.copytree(root / "out", out)
    with sqlite3.connect(out / DB_FILE) as db:
        [(key, map_dir)] = db.execute(
            "SELECT key, json_extract(config, '$.map_dir') FROM episodes WHERE kind = 'recall'"
            " LIMIT 1"
        ).fetchall()
        moved = str(Path(map_dir).parent.with_name("small-0123456789-fedcba9876") / "sift")
        db.execute(
            "UPDATE episodes SET config = json_set(config, '$.map_dir', ?) WHERE key = ?",
            (moved, key),
        )
    plan = load_experiment(root / "tiny.yaml").with_output(out)
    with pytest.raises(StoreError, match=f"episode {key} .* captured again with other content"):
        run_experiment(plan, progress=False)


def test_a_run_on_the_hidden_set_writes_neither_its_seed_nor_its_towns_specs(tmp_path, monkeypatch):
    """Only rendered images, results and the seed's digest: no file of the store, the cache or
    the report holds the seed, a town's own seed or any field of its spec."""
    from vlocbench.bench.report import write_report
    from vlocbench.sim.generation import HIDDEN_SEED_ENV, seed_digest
    from vlocbench.sim.town import load_town_spec

    seed = 2**52 + 977
    monkeypatch.setenv(HIDDEN_SEED_ENV, str(seed))
    plan = load_experiment(
        {
            "name": "hidden",
            "towns": [{"hidden": {"count": 1, "style": "city"}}],
            "route_length_m": 50,
            "methods": [{"name": "oracle", "kind": "oracle"}],
            "repetitions": 1,
            "baseline_repetitions": 1,
            "gallery": {"camera": {"intrinsics": {"width": 160, "height": 120}}},
            "output": str(tmp_path / "out"),
            "cache": str(tmp_path / "cache"),
        }
    )
    [town] = plan.spec.towns
    assert town == f"hidden-{seed_digest(seed)}-city-0"
    summary = run_experiment(plan, progress=False)
    assert (summary.finished, summary.errors) == (3, 0)
    write_report(tmp_path / "out", examples=False)
    spec = load_town_spec(town)
    secrets = [str(seed), str(spec.seed), "block_widths_m", "beach_side", "tower_floors"]
    files = [p for p in tmp_path.rglob("*") if p.is_file()]
    assert any(p.suffix == ".html" for p in files)
    for path in files:
        content = path.read_bytes()
        for secret in secrets:
            assert secret.encode() not in content, (path, secret)


def test_recall_drives_of_several_methods_share_a_drive_in_a_run(tiny, tmp_path):
    """The recall episodes of ``sift`` and a gated ``sift`` in one setup drive once (one worker
    job): each stores what it stores when driven alone."""
    import yaml

    root, _ = tiny
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    gated = {"name": "sift-40", "features": "sift", "matcher": "nn-ratio", "retrieval": "vlad"}
    gated["localizer"] = {"min_inliers": 40}
    recall_only = {**spec, "failure": False, "baseline": False, "methods": ["sift", gated]}
    shared = run_experiment(
        load_experiment({**recall_only, "output": str(tmp_path / "shared")}), progress=False
    )
    alone = run_experiment(
        load_experiment({**recall_only, "methods": [gated], "output": str(tmp_path / "alone")}),
        progress=False,
    )
    assert (shared.finished, shared.errors, alone.finished) == (4, 0, 2)
    rows = {}
    for folder in (root / "out", tmp_path / "alone", tmp_path / "shared"):
        with ResultStore(folder, "tiny") as store:
            rows[folder.name] = {r.key: r.metrics for r in store.rows() if r.kind == "recall"}
    solo = {**rows["out"], **rows["alone"]}
    assert set(rows["shared"]) == set(solo)
    for key, metrics in rows["shared"].items():
        for name in ("queries", "recall", "recall_ekf", "place_recall", "lock_losses_per_km"):
            assert getattr(metrics, name) == getattr(solo[key], name), name
    answered = sorted(m.recall[-1] for m in rows["shared"].values())
    assert answered[0] < answered[-1]  # the two methods differ: the comparison can fail


def test_a_store_carried_to_another_platform_is_named_as_its_run_resumes(tiny, tmp_path, caplog):
    import shutil

    root, _ = tiny
    out = tmp_path / "out"
    shutil.copytree(root / "out", out)
    with sqlite3.connect(out / DB_FILE) as db:  # as if run on a machine that draws otherwise
        db.execute("UPDATE episodes SET platform = '0123456789ab'")
        db.execute("DELETE FROM episodes WHERE kind = 'baseline'")  # one episode left to run
    plan = load_experiment(root / "tiny.yaml").with_output(out)
    with caplog.at_level("WARNING"):
        again = run_experiment(plan, progress=False)
    assert (again.skipped, again.finished) == (4, 1)
    here = current_platform().id
    assert f"this machine is platform {here}; the store's episodes ran on others (4 on " in (
        caplog.text
    )
    with ResultStore(out, "tiny") as store:
        assert store.platform_counts() == {"0123456789ab": 4, here: 1}
    caplog.clear()
    with caplog.at_level("WARNING"):  # nothing left to run: nothing to say
        run_experiment(plan, progress=False)
    assert "this machine is platform" not in caplog.text


def test_a_run_takes_the_episodes_it_shares_with_another_experiments_store(tiny, tmp_path):
    """Keys hash what determines an episode, not the experiment: another experiment's store
    gives the episodes both plan (k = 6 and the odometry line), copied as they are, and only the
    rest are driven."""
    import yaml

    from vlocbench.results import episodes

    root, _ = tiny
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    other = {**spec, "name": "other", "sweep": {"illumination.k": [6, 8]}}
    other["output"] = str(tmp_path / "other")
    (tmp_path / "other.yaml").write_text(yaml.safe_dump(other))
    plan = load_experiment(tmp_path / "other.yaml")
    summary = run_experiment(plan, progress=False, reuse=[root / "out"])
    assert (summary.total, summary.skipped, summary.reused) == (5, 3, 3)
    assert (summary.finished, summary.errors) == (2, 0)  # k = 8's recall and failure drives
    df = episodes(tmp_path / "other", tmp_path / "other.yaml")
    before = episodes(root / "out", root / "tiny.yaml").set_index("key")
    shared = df[df.key.isin(before.index)]
    assert sorted(shared.kind) == ["baseline", "failure", "recall"]
    assert set(shared.setup) <= {"illumination.k=6", "illumination.k=8"}  # this plan's labels
    for column in ("failures_per_km", "distance_driven_m", "platform"):
        assert list(shared[column]) == list(before.loc[shared.key, column]), column
    assert set(df[~df.key.isin(before.index)].setup) == {"illumination.k=8"}
    again = run_experiment(plan, progress=False, reuse=[root / "out"])
    assert (again.skipped, again.reused, again.finished) == (5, 0, 0)


def test_a_rerun_builds_only_the_maps_its_remaining_episodes_need(tiny, tmp_path):
    """A store whose episodes are all done, with its galleries in the cache and no map: the rerun
    builds no map and drives nothing; the map is built when a new setup needs it."""
    import shutil

    import yaml

    from vlocbench.loc.mapping import MAP_FILE

    root, _ = tiny
    shutil.copytree(root / "out", tmp_path / "out")
    shutil.copytree(root / "cache" / "galleries", tmp_path / "cache" / "galleries")
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    spec.update(output=str(tmp_path / "out"), cache=str(tmp_path / "cache"))
    again = run_experiment(load_experiment(spec), progress=False)
    assert (again.skipped, again.finished) == (5, 0)
    assert not list((tmp_path / "cache").rglob(MAP_FILE))
    spec["sweep"] = {"illumination.k": [0, 6, 8]}
    more = run_experiment(load_experiment(spec), progress=False)
    assert (more.skipped, more.finished, more.errors) == (5, 2, 0)
    [built] = (tmp_path / "cache" / "maps").rglob(MAP_FILE)
    [before] = (root / "cache" / "maps").rglob(MAP_FILE)
    assert built.relative_to(tmp_path) == before.relative_to(root)  # the same map's folder
