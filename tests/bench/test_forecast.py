"""What a run would do, read from its store and the cache without making or writing anything."""

import dataclasses
import json
import statistics

import pytest
import yaml

from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.forecast import MapBuild, forecast
from vlocbench.bench.store import DB_FILE, StoreError, read_episodes
from vlocbench.config import to_dict
from vlocbench.sim.town import TownSpec

from ..conftest import small_spec


def _spec(root, **changes):
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    spec.update(changes)
    return spec


def _stored_state(root):
    db = root / "out" / DB_FILE
    return sorted((r.key, r.wall_s) for r in read_episodes(root / "out")), db.stat().st_mtime_ns


def test_a_finished_store_has_nothing_left_and_a_new_level_is_timed_by_its_stored_drives(tiny):
    root, _ = tiny
    before = _stored_state(root)
    done = forecast(load_experiment(root / "tiny.yaml"))
    assert (done.planned, done.to_run, done.reusable) == (5, 0, 0)
    assert done.galleries_to_make == () and done.maps_to_build == () and done.worker_s == 0
    assert done.lines(2) == [f"tiny ({root / 'out'}): 5 episodes, 5 done, 0 to run"]

    # a third level: its recall and failure drives are left, timed by the stored ones of k = 0, 6
    more = forecast(load_experiment(_spec(root, sweep={"illumination.k": [0, 6, 8]})))
    assert (more.planned, more.to_run) == (7, 2) and more.maps_to_build == ()
    rows = read_episodes(root / "out")
    for g in more.groups:
        stored = [r.wall_s for r in rows if (r.method, r.kind) == (g.method, g.kind)]
        assert g.episode_s == pytest.approx(statistics.median(stored)) and not g.estimated
        assert g.to_run == (g.kind != "baseline")
    left = {(g.method, g.kind): g for g in more.groups if g.to_run}
    assert more.worker_s == pytest.approx(sum(g.episode_s for g in left.values()))
    text = more.lines(2)
    assert text[1].startswith("  sift recall: 1 of 3 left, ") and "of a worker" in text[1]
    assert text[3].startswith("all: 2 of 7 left, ") and text[3].endswith(" on 2 worker(s)")
    assert _stored_state(root) == before  # read without a run, a lock or a write


def test_a_town_without_stored_drives_is_timed_per_metre_and_a_new_cache_has_all_to_make(tiny):
    root, _ = tiny
    twin = dataclasses.replace(small_spec(), name="small-twin")
    assert isinstance(twin, TownSpec)
    (root / "twin.yaml").write_text(yaml.safe_dump(to_dict(twin)))
    towns = [str(root / "small.yaml"), str(root / "twin.yaml")]
    f = forecast(load_experiment(_spec(root, towns=towns)))
    rows = read_episodes(root / "out")
    twin_groups = [g for g in f.groups if g.town == "small-twin"]
    assert {g.kind for g in twin_groups} == {"recall", "failure", "baseline"}
    for g in twin_groups:  # the same route's length: the same time as small's drives
        stored = [r.wall_s for r in rows if (r.method, r.kind) == (g.method, g.kind)]
        assert g.estimated and g.episode_s == pytest.approx(statistics.median(stored))
    # the twin's map, timed by small's: the same route, a gallery of about as many images (its
    # capture not yet made, one image a spacing of the route, where small's drive stopped short)
    small_map = json.loads(next((root / "cache" / "maps").glob("*/*/map.json")).read_text())
    build_s = sum(small_map["report"]["seconds"].values())
    assert f.maps_to_build == (MapBuild("small-twin", "sift", pytest.approx(build_s, rel=0.05)),)
    assert f.map_worker_s == f.maps_to_build[0].worker_s
    assert f.galleries_to_make == ("small-twin",)
    text = f.lines(2)
    assert text[2].startswith("maps to build: small-twin sift (~")
    assert text[-3].startswith("maps: ~") and text[-3].endswith(" on 2 worker(s)")
    assert text[-1].startswith("(times: ") and "maps: the median rates" in text[-1]

    fresh = root / "fresh"
    new = forecast(load_experiment(_spec(root, output=str(fresh), cache=str(fresh / "cache"))))
    assert (new.to_run, new.worker_s, new.untimed) == (5, 0, 5)
    assert new.galleries_to_make == ("small",)
    assert new.maps_to_build == (MapBuild("small", "sift", None),) and new.map_worker_s == 0
    assert new.lines(2)[-1] == "all: 5 of 5 left, 5 with no time yet"
    assert not fresh.exists()


def test_episodes_another_store_has_are_counted_done_and_the_cli_makes_nothing(tiny, capsys):
    from vlocbench.cli import main

    root, _ = tiny
    other = root / "other"
    reused = forecast(load_experiment(_spec(root, output=str(other))), reuse=[root / "out"])
    assert (reused.to_run, reused.reusable) == (0, 5)
    before = _stored_state(root)
    (root / "more.yaml").write_text(yaml.safe_dump(_spec(root, output=str(other))))
    assert main(["run", str(root / "more.yaml"), "--dry-run", "--reuse", str(root / "out")]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"tiny ({other}): 5 episodes, 5 done (5 of them to copy from other")
    assert not other.exists() and _stored_state(root) == before
    with pytest.raises(StoreError, match="holds no vlocbench results"):  # as the run says
        forecast(load_experiment(root / "more.yaml"), reuse=[root / "no-store"])
