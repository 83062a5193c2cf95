"""Executors: inline, a local pool that survives dead workers and stops on a signal, Dask on
loopback; every outcome stored as it arrives."""

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.bench.fakes import CONTROL_ENV, fake_tasks, run_fake
from tests.conftest import assert_stops_cleanly
from vlocbench.bench.executors import execute
from vlocbench.bench.store import DB_FILE, ResultStore


def test_local_pool_retries_the_episode_of_a_dead_worker(tmp_path, control):
    tasks = fake_tasks()
    (control / "die-illumination.k=6-sift-1").touch()  # one failure episode's worker dies once
    (control / "always-die-illumination.k=0-sift-0").touch()  # these die on every attempt
    with ResultStore(tmp_path / "out", "fake") as store:
        e = execute(tasks, store, workers=2, runner=run_fake, progress=False)
        finished, errors, retried = e.finished, e.errors, e.retried
        rows = {(r.setup, r.kind, r.repetition): r for r in store.rows(None) or []}
        done = store.done_keys()
    # the two always-dying tasks (recall and failure rep 0 at k = 0) end as errors after 3 attempts
    assert errors == 2 and finished == len(tasks) - 2
    assert retried >= 1 + 2 * 2
    assert len(done) == len(tasks) - 2
    with sqlite3.connect(tmp_path / "out" / DB_FILE) as db:
        got = dict(db.execute("SELECT status, COUNT(*) FROM episodes GROUP BY status").fetchall())
        died = db.execute("SELECT error, attempts FROM episodes WHERE status='error'").fetchall()
    assert got == {"ok": len(tasks) - 2, "error": 2}
    assert died == [("its worker process died", 3)] * 2
    assert rows == {}  # no run was started: rows() lists a run's episodes only


_DRIVER = """
import sys
from tests.bench.fakes import fake_tasks, run_fake
from vlocbench.bench.executors import execute
from vlocbench.bench.store import ResultStore
from vlocbench.cli import _signals_interrupt

scheduler = sys.argv[2] if len(sys.argv) > 2 else None
with ResultStore(sys.argv[1], "fake") as store, _signals_interrupt():
    try:
        execute(fake_tasks(), store, workers=2, scheduler=scheduler, runner=run_fake,
                progress=False)
    except KeyboardInterrupt:
        sys.exit(130)
"""


def _committed(db_path):
    """Episodes stored without error, read beside the driver that writes them (SQLite's WAL)."""
    if not db_path.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db_path}?mode=ro", uri=True, timeout=1) as db:
            return db.execute("SELECT COUNT(*) FROM episodes WHERE status='ok'").fetchone()[0]
    except sqlite3.OperationalError:  # the schema is still being created
        return 0


def _children(pid):
    """Processes whose parent is ``pid`` (from /proc)."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pids):
    alive = []
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.append(pid)
    return alive


def _environment_at_start(_: int) -> dict[str, str]:
    """This process's environment as it was given at its start (Linux), before any module ran."""
    raw = Path("/proc/self/environ").read_bytes().decode(errors="replace")
    return dict(entry.split("=", 1) for entry in raw.split("\0") if "=" in entry)


def test_pool_workers_start_with_one_thread_each_and_the_driver_keeps_its_own(monkeypatch):
    # numpy's OpenBLAS reads its threads as numpy loads, before the pool's initializer runs
    from vlocbench.bench.executors import worker_pool
    from vlocbench.bench.worker import WORKER_THREADS_ENV

    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "7")
    monkeypatch.delenv("LP_NUM_THREADS", raising=False)
    with worker_pool(2) as pool:
        started = list(pool.map(_environment_at_start, range(4)))
    for env in started:
        assert {k: env.get(k) for k in WORKER_THREADS_ENV} == WORKER_THREADS_ENV
    assert os.environ["OPENBLAS_NUM_THREADS"] == "7" and "LP_NUM_THREADS" not in os.environ


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT])
def test_a_killed_or_interrupted_run_leaves_no_process_and_a_consistent_store(
    tmp_path, control, how
):
    (control / "sleep-illumination.k=0-sift-0").write_text("0")  # its two episodes finish
    (control / "sleep-all").write_text("60")
    env = {**os.environ, "PYTHONPATH": os.getcwd(), CONTROL_ENV: str(control)}
    driver = subprocess.Popen(
        [sys.executable, "-c", _DRIVER, str(tmp_path / "out")],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while len(_children(driver.pid)) < 3 and time.monotonic() < deadline:  # 2 workers, tracker
        time.sleep(0.2)
    workers = _children(driver.pid)
    assert len(workers) >= 2, workers
    # the signal comes once the two quick episodes are committed (not after a fixed wait, which
    # a loaded machine outlasts), while the others sleep in the workers
    while _committed(tmp_path / "out" / DB_FILE) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert_stops_cleanly(driver, how, -signal.SIGKILL if how == signal.SIGKILL else 130)
    deadline = time.monotonic() + 30  # a worker still starting up notices once it has started
    while _alive(workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert _alive(workers) == []
    with ResultStore(tmp_path / "out", "fake") as store:  # the lock is free, the store whole
        done = store.done_keys()
        assert len(done) == 2
        for key in done:
            assert store.read_table(key, "trajectory")["time_s"].shape == (50,)


@pytest.fixture
def dask_cluster(tmp_path):
    """Two single-threaded Dask worker processes on loopback."""
    distributed = pytest.importorskip("distributed")
    import dask

    # one job at a time on each worker, so a worker's death catches exactly the job it runs
    # (Dask's default saturation, 1.1, sometimes queues a second job on a one-thread worker)
    with (
        dask.config.set({"distributed.scheduler.worker-saturation": 1.0}),
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            local_directory=str(tmp_path / "dask"),
        ) as cluster,
    ):
        yield cluster


def test_dask_cluster_on_loopback(tmp_path, control, dask_cluster):
    tasks = fake_tasks()
    (control / "die-illumination.k=6-sift-1").touch()
    with ResultStore(tmp_path / "out", "fake") as store:
        e = execute(
            tasks, store, scheduler=dask_cluster.scheduler_address, runner=run_fake, progress=False
        )
        assert store.done_keys() == {t.key for t in tasks}
    assert (e.finished, e.errors) == (len(tasks), 0)
    assert e.slots == 2  # the cluster's threads, whatever --workers says
    assert (e.workers_lost, e.retried) == (1, 1)  # the summary says a worker died
    assert not (control / "die-illumination.k=6-sift-1").exists()  # it did die, once


def test_an_interrupted_dask_run_leaves_the_cluster_idle(tmp_path, control, dask_cluster):
    """Dask cannot stop a task that is running, but nothing else of the run may stay queued."""
    from distributed import Client

    (control / "sleep-all").write_text("2")  # 8 episodes on 2 workers: about 8 s
    env = {**os.environ, "PYTHONPATH": os.getcwd(), CONTROL_ENV: str(control)}
    with Client(dask_cluster.scheduler_address) as client:
        driver = subprocess.Popen(
            [sys.executable, "-c", _DRIVER, str(tmp_path / "out"), dask_cluster.scheduler_address],
            env=env,
            stderr=subprocess.PIPE,
            text=True,
        )
        deadline = time.monotonic() + 60
        while not client.processing() or not any(client.processing().values()):
            assert time.monotonic() < deadline, "the run never started"
            time.sleep(0.1)
        assert_stops_cleanly(driver, signal.SIGTERM, 130)
        # the episodes in flight finish (2 s); none of the queued ones starts
        deadline = time.monotonic() + 20
        while client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)):
            assert time.monotonic() < deadline, client.processing()
            time.sleep(0.2)
    with ResultStore(tmp_path / "out", "fake") as store:
        assert len(store.done_keys()) < len(fake_tasks())


def test_an_unreachable_scheduler_is_a_clear_error(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    from vlocbench.bench import executors
    from vlocbench.errors import ConfigError

    monkeypatch.setattr(executors, "CONNECT_TIMEOUT_S", 1)
    with ResultStore(tmp_path, "fake") as store, pytest.raises(ConfigError, match="cannot reach"):
        execute(fake_tasks(), store, scheduler="tcp://127.0.0.1:9", runner=run_fake, progress=False)


def test_a_dask_cluster_of_unlike_machines_is_named_before_its_episodes(tmp_path, caplog):
    """Two workers, one of them drawing with Mesa's other rasterizer (as another machine's
    driver would): the run says so before any episode."""
    distributed = pytest.importorskip("distributed")
    from vlocbench.bench.platform import current_platform

    if "llvmpipe" not in current_platform().details["gl_renderer"]:
        pytest.skip("Mesa's softpipe is the unlike renderer tried; this machine has no llvmpipe")
    nanny = {"cls": distributed.Nanny, "options": {"nthreads": 1, "host": "127.0.0.1"}}
    softpipe = {**nanny, "options": {**nanny["options"], "env": {"GALLIUM_DRIVER": "softpipe"}}}
    scheduler = {
        "cls": distributed.Scheduler,
        "options": {"host": "127.0.0.1", "dashboard_address": None},
    }
    with (
        distributed.SpecCluster(
            scheduler=scheduler, workers={"llvmpipe": nanny, "softpipe": softpipe}
        ) as cluster,
        ResultStore(tmp_path / "out", "fake") as store,
        caplog.at_level("WARNING"),
    ):
        cluster.wait_for_workers(2)
        address = cluster.scheduler_address
        execute(fake_tasks()[:2], store, scheduler=address, runner=run_fake, progress=False)
    assert "the Dask cluster's workers are on 2 platforms (" in caplog.text
    assert current_platform().id in caplog.text
