"""Stored episodes driven again: the same to the last digit, and a changed drive named."""

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from vlocbench.bench.platform import current_platform
from vlocbench.bench.store import DB_FILE, EPISODES_DIR, StoreError
from vlocbench.bench.verify import verify_episodes
from vlocbench.errors import ConfigError, UnknownNameError


def test_a_stored_episode_driven_again_is_the_same_and_a_changed_drive_is_named(tiny, monkeypatch):
    import vlocbench.nav.ekf as ekf

    root, _ = tiny
    [v] = verify_episodes(root / "out", count=1, kinds=["failure"])
    assert v.same is True and v.differences == () and v.same_platform
    assert v.platform == current_platform().id and v.row.kind == "failure"
    assert v.line() == f"{v.row.town} sift failure {v.row.setup} rep 0 ({v.row.key}): the same " + (
        f"to the last digit ({v.wall_s / 60:.1f} min)"  # its own drive's time, whatever the load
    )
    # the code changes what the key drives (the EKF's variance at a start), the key does not
    monkeypatch.setattr(ekf, "_KNOWN_VAR", 1e-3)
    [v] = verify_episodes(root / "out", keys=[v.row.key])
    assert v.same is False
    assert "DIFFERS on this platform, as it was stored: the code changed what this key" in v.line()
    assert any(d.startswith("trajectory step ") and " in ekf_" in d for d in v.differences)


def test_a_stored_result_unlike_its_drive_is_found_where_it_differs(tiny, tmp_path):
    import shutil

    root, _ = tiny
    out = tmp_path / "out"
    shutil.copytree(root / "out", out)
    [v] = verify_episodes(out, count=1, kinds=["baseline"])
    path = out / EPISODES_DIR / v.row.key / "trajectory.parquet"
    table = pq.read_table(path).to_pydict()
    table["true_x_m"][7] += 1e-9  # a nanometre, at step 7
    pq.write_table(pa.Table.from_pydict(table), path)
    [v] = verify_episodes(out, keys=[v.row.key])
    assert v.same is False
    assert v.differences[0].startswith("trajectory step 7 (t = 0.35 s) first differs, in true_x_m")


def test_bad_choices_are_named(tiny, tmp_path):
    import shutil
    import sqlite3

    root, _ = tiny
    with pytest.raises(
        UnknownNameError,
        match=r"--kinds: unknown episode kind .drive.; valid: baseline, failure, recall",
    ):
        verify_episodes(root / "out", kinds=["drive"])
    with pytest.raises(
        UnknownNameError, match=r"--methods: unknown method 'orb'; valid: odometry, sift"
    ):
        verify_episodes(root / "out", methods=["orb"])
    with pytest.raises(ConfigError, match="--key: no finished episode of this store has key x"):
        verify_episodes(root / "out", keys=["x"])
    # an episode whose map is no longer in the cache cannot be driven as it was
    shutil.copytree(root / "out", tmp_path / "out")
    with sqlite3.connect(tmp_path / "out" / DB_FILE) as db:
        [(key,)] = db.execute("SELECT key FROM episodes WHERE kind = 'failure' LIMIT 1").fetchall()
        db.execute(
            "UPDATE episodes SET config = json_set(config, '$.map_dir', ?) WHERE key = ?",
            (str(tmp_path / "gone"), key),
        )
    with pytest.raises(StoreError, match=f"map {tmp_path / 'gone'}, which is no longer there"):
        verify_episodes(tmp_path / "out", keys=[key])


def test_an_episode_does_not_depend_on_the_jobs_before_it_in_its_process(tiny):
    """A worker keeps its town's scene and its last localizers between jobs: each episode driven
    again after others than it followed in the run (the reverse order, light and dark between)
    comes back the same."""
    from vlocbench.bench.store import read_latest_run

    root, _ = tiny
    rows = [r for r in read_latest_run(root / "out")[1] if r.kind != "baseline"]
    keys = [r.key for r in sorted(rows, key=lambda r: (r.kind, r.setup), reverse=True)]
    verdicts = verify_episodes(root / "out", keys=[*keys, keys[0]])
    assert [v.row.key for v in verdicts] == [*keys, keys[0]]
    assert all(v.same for v in verdicts), [v.line() for v in verdicts if not v.same]
