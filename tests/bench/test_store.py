import dataclasses
import errno
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from tests.bench.fakes import synthetic_result
from vlocbench.bench.metrics import episode_metrics
from vlocbench.bench.platform import Platform
from vlocbench.bench.store import (
    DB_FILE,
    EpisodeRow,
    ResultStore,
    StoreError,
    read_latest_run,
    read_platforms,
)


def _row(key, status="ok"):
    ok = status == "ok"
    metrics = dataclasses.replace(
        episode_metrics(synthetic_result(1)), ct_mean_s=float("nan"), recall=(0.5, float("inf"))
    )
    return EpisodeRow(
        key=key,
        kind="failure",
        town="town10",
        method="sift",
        setup="k=0",
        repetition=0,
        seed=0,
        config={"a": 1},
        status=status,
        error=None if ok else "boom",
        metrics=metrics if ok else None,
        wall_s=1.5,
        attempts=1,
    )


def test_write_read_and_resume_keys(tmp_path):
    with ResultStore(tmp_path, "exp") as store:
        store.start_run("run1", {"name": "exp"}, ["a", "b", "c"])
        store.write_episode(_row("a"), synthetic_result(2))
        store.write_episode(_row("b", "error"), None)
        assert store.done_keys() == {"a"}  # an errored episode runs again
        rows = store.rows()
        assert [(r.key, r.status) for r in rows] == [("a", "ok"), ("b", "error")]
        # NaN and infinities are stored as null (strict JSON) and read back as NaN
        assert np.isnan(rows[0].metrics.ct_mean_s) and np.isnan(rows[0].metrics.recall[1])
        assert store.db.execute(
            "SELECT json_extract(metrics, '$.ct_mean_s') IS NULL FROM episodes WHERE key='a'"
        ).fetchone() == (1,)
        traj = store.read_table("a", "trajectory")
        assert traj["true_x_m"].shape == (50,) and traj["ekf_x_m"][0] == pytest.approx(0.1)
        locs = store.read_table("a", "localizations")
        assert list(locs["success"]) == [True] * 4
        # the localizer's time by stage, a dict a query (empty where it reported none)
        assert list(locs["stage_s"]) == [{"features": 0.03, "pnp": 0.02}, {}] * 2
    # a second run of the same experiment: new run, old episodes found by key
    with ResultStore(tmp_path, "exp") as store:
        store.start_run("run2", {"name": "exp"}, ["a", "d"])
        assert store.done_keys() == {"a"}
        assert [r.key for r in store.rows()] == ["a"]
        assert [r.key for r in store.rows("run1")] == ["a", "b"]


def test_rows_stored_with_nan_before_strict_json_are_rewritten_on_open(tmp_path):
    with ResultStore(tmp_path, "exp") as store:
        store.start_run("run1", {"name": "exp"}, ["a"])
        store.write_episode(_row("a"), synthetic_result(2))
    with sqlite3.connect(tmp_path / DB_FILE) as db:  # as an older vlocbench wrote them
        db.execute("""UPDATE episodes SET metrics='{"ct_mean_s": NaN, "failures": 1}'""")
        db.execute("""UPDATE runs SET spec='{"name": "exp", "x": Infinity}'""")
    with ResultStore(tmp_path, "exp") as store:
        assert store.db.execute(
            "SELECT json_valid(metrics), json_extract(metrics, '$.failures') FROM episodes"
        ).fetchall() == [(1, 1)]
        assert store.db.execute("SELECT spec FROM runs").fetchall() == [
            ('{"name": "exp", "x": null}',)
        ]
        assert np.isnan(store.rows()[0].metrics.ct_mean_s)


def _platform(render):
    packages = {"mujoco": "4.0.1"}
    return Platform(render, "n" * 16, "", packages, {"gl_renderer": "llvmpipe", "cpu": "x"})


def test_each_episode_names_its_platform_and_a_store_from_before_takes_the_column(tmp_path):
    a, b = _platform("r" * 16), _platform("s" * 16)
    with ResultStore(tmp_path / "new", "exp") as store:
        store.start_run("run1", {"name": "exp"}, ["a", "b", "c"])
        store.write_episode(dataclasses.replace(_row("a"), platform=a.id), synthetic_result(1), a)
        store.write_episode(dataclasses.replace(_row("b"), platform=a.id), synthetic_result(1), a)
        store.write_episode(dataclasses.replace(_row("c"), platform=b.id), synthetic_result(1), b)
    assert [r.platform for r in read_latest_run(tmp_path / "new")[1]] == [a.id, a.id, b.id]
    assert read_platforms(tmp_path / "new") == {a.id: a.to_dict(), b.id: b.to_dict()}
    # a store written before platforms were recorded: read as it is (none known), and a run
    # that opens it adds the column, its old rows without a platform
    old = tmp_path / "old"
    with ResultStore(old, "exp") as store:
        store.start_run("run1", {"name": "exp"}, ["a", "b"])
        store.write_episode(_row("a"), synthetic_result(1))
    with sqlite3.connect(old / DB_FILE) as db:
        db.execute("DROP TABLE platforms")
        db.execute("ALTER TABLE episodes DROP COLUMN platform")
    assert read_platforms(old) == {} and read_latest_run(old)[1][0].platform is None
    with ResultStore(old, "exp") as store:
        store.write_episode(dataclasses.replace(_row("b"), platform=a.id), synthetic_result(1), a)
        assert [r.platform for r in store.rows()] == [None, a.id]
    assert read_platforms(old) == {a.id: a.to_dict()}


def test_another_experiments_folder_and_a_busy_folder_are_refused(tmp_path):
    with (
        ResultStore(tmp_path, "exp"),
        pytest.raises(StoreError, match="in use by another vlocbench run"),
    ):
        ResultStore(tmp_path, "exp").__enter__()
    with pytest.raises(StoreError, match="holds results of experiment 'exp', not 'other'"):
        ResultStore(tmp_path, "other").__enter__()
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / DB_FILE).write_text("not a database" * 100)
    with pytest.raises(StoreError, match="not a vlocbench store"):
        ResultStore(tmp_path / "junk", "exp").__enter__()


def test_a_full_disk_leaves_the_store_as_it_was(tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    with ResultStore(tmp_path, "exp") as store:
        store.write_episode(_row("a"), synthetic_result(1))
        real = pq.write_table
        calls = []

        def full(table, where, **kw):
            calls.append(where)
            if len(calls) == 2:  # the second table of the episode
                raise OSError(errno.ENOSPC, "No space left on device")
            return real(table, where, **kw)

        monkeypatch.setattr(pq, "write_table", full)
        with pytest.raises(StoreError, match=r"episode b .*\(disk full\).*rerun to resume"):
            store.write_episode(_row("b"), synthetic_result(1))
        assert store.done_keys() == {"a"}
        assert sorted(p.name for p in (tmp_path / "episodes").iterdir()) == ["a"]
    with sqlite3.connect(tmp_path / DB_FILE) as db:
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)


def test_kill_9_loses_only_the_episode_in_flight(tmp_path):
    """A driver killed with SIGKILL mid-write: the store stays readable; a rerun finishes the
    rest without duplicates."""
    script = textwrap.dedent(f"""
        import time
        from tests.bench.fakes import synthetic_result
        from tests.bench.test_store import _row
        from vlocbench.bench.store import ResultStore
        with ResultStore({str(tmp_path)!r}, "exp") as store:
            store.start_run("r", {{}}, [f"k{{i}}" for i in range(100)])
            for i in range(100):
                if f"k{{i}}" not in store.done_keys():
                    store.write_episode(_row(f"k{{i}}"), synthetic_result(1))
                    print(i, flush=True)
                time.sleep(0.02)
    """)
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    proc = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, env=env
    )
    for _ in range(10):  # let it store ten episodes, then kill it in the middle of the loop
        proc.stdout.readline()
    time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    with ResultStore(tmp_path, "exp") as store:
        done = store.done_keys()
        assert 10 <= len(done) < 100
        for key in done:  # every committed episode has its tables
            assert store.read_table(key, "trajectory")["time_s"].shape == (50,)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    assert len(proc.stdout.split()) == 100 - len(done)  # only the missing ones ran
    with sqlite3.connect(tmp_path / DB_FILE) as db:
        assert db.execute("SELECT COUNT(*), COUNT(DISTINCT key) FROM episodes").fetchone() == (
            100,
            100,
        )
        assert db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    assert sorted(p.name for p in (tmp_path / "episodes").iterdir()) == sorted(
        f"k{i}" for i in range(100)
    )


def test_another_stores_finished_episodes_are_adopted_as_they_are(tmp_path):
    a, b = _platform("r" * 16), _platform("s" * 16)
    src = tmp_path / "src"
    with ResultStore(src, "other") as store:
        store.start_run("run1", {"name": "other"}, ["a", "b", "c", "d"])
        store.write_episode(dataclasses.replace(_row("a"), platform=a.id), synthetic_result(2), a)
        store.write_episode(_row("b", "error"), None)
        store.write_episode(dataclasses.replace(_row("c"), platform=b.id), synthetic_result(1), b)
        store.write_episode(_row("d"), synthetic_result(1))
    (src / "episodes" / "d").rename(src / "episodes" / "d-lost")  # a damaged store's row
    with sqlite3.connect(src / DB_FILE) as db:  # as an older vlocbench wrote them
        db.execute(
            """UPDATE episodes SET metrics='{"ct_mean_s": NaN, "failures": 2}' WHERE key='c'"""
        )
        stored = dict(db.execute("SELECT key, finished FROM episodes"))
    dst = tmp_path / "dst"
    with ResultStore(dst, "exp") as store:
        store.start_run("run1", {"name": "exp"}, ["a", "b", "c", "d", "e"])
        # the error and the row without its tables are left to run; a key it lacks, too
        assert store.adopt(src, ["a", "b", "c", "d", "e"]) == ["a", "c"]
        assert store.done_keys() == {"a", "c"}
        assert store.adopt(src, ["a", "c"]) == []  # nothing twice
        # its row as it is (when and where it ran included)
        with sqlite3.connect(src / DB_FILE) as db:
            query = "SELECT * FROM episodes WHERE key='a'"
            assert store.db.execute(query).fetchall() == db.execute(query).fetchall()
        rows = {r.key: r for r in store.rows()}
        assert rows["a"].platform == a.id and rows["c"].platform == b.id
        assert rows["c"].metrics.failures == 2 and np.isnan(rows["c"].metrics.ct_mean_s)
        assert dict(store.db.execute("SELECT key, finished FROM episodes")) == {
            k: stored[k] for k in ("a", "c")
        }
        assert store.db.execute(
            "SELECT count(*) FROM episodes WHERE NOT json_valid(metrics)"
        ).fetchone() == (0,)
        for name in ("trajectory", "localizations"):
            for key in ("a", "c"):
                assert (dst / "episodes" / key / f"{name}.parquet").read_bytes() == (
                    src / "episodes" / key / f"{name}.parquet"
                ).read_bytes()
        with pytest.raises(StoreError, match="this run's own output folder"):
            store.adopt(dst, ["a"])
        with pytest.raises(StoreError, match="holds no vlocbench results"):
            store.adopt(tmp_path / "nothing", ["a"])
    assert read_platforms(dst) == {a.id: a.to_dict(), b.id: b.to_dict()}
    # a store from before platforms were recorded gives its episodes without one
    with sqlite3.connect(src / DB_FILE) as db:
        db.execute("DROP TABLE platforms")
        db.execute("ALTER TABLE episodes DROP COLUMN platform")
    with ResultStore(tmp_path / "dst2", "exp") as store:
        assert store.adopt(src, ["a"]) == ["a"]
        assert store.db.execute("SELECT platform FROM episodes").fetchall() == [(None,)]
