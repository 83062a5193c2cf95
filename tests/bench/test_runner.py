import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pycolmap
import pytest
import yaml

from tests.bench.fakes import CONTROL_ENV, run_fake
from tests.conftest import call_behind_build_lock, small_spec
from vlocbench.bench.experiment import load_experiment, plan_from_stored
from vlocbench.bench.runner import execute, prepare_maps, run_experiment
from vlocbench.bench.store import DB_FILE, ResultStore, read_latest_run
from vlocbench.bench.summary import summarize
from vlocbench.config import to_dict
from vlocbench.loc.mapping import MAP_FILE


def _fake_tasks():
    spec = load_experiment({"name": "fake", "towns": ["town10"], "methods": ["sift-vlad"],
                            "sweep": {"illumination.k": [0, 6]}, "repetitions": 2})  # fmt: skip
    return spec.tasks()  # 2 x (1 + 2) + 10 = 16


@pytest.fixture
def control(tmp_path, monkeypatch):
    folder = tmp_path / "control"
    folder.mkdir()
    monkeypatch.setenv(CONTROL_ENV, str(folder))
    return folder


def test_local_pool_retries_the_episode_of_a_dead_worker(tmp_path, control):
    tasks = _fake_tasks()
    (control / "die-illumination.k=6-sift-vlad-1").touch()  # one failure episode's worker dies once
    (control / "always-die-illumination.k=0-sift-vlad-0").touch()  # these die on every attempt
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
from tests.bench.fakes import run_fake
from tests.bench.test_runner import _fake_tasks
from vlocbench.bench.runner import execute
from vlocbench.bench.store import ResultStore
from vlocbench.cli import _signals_interrupt

scheduler = sys.argv[2] if len(sys.argv) > 2 else None
with ResultStore(sys.argv[1], "fake") as store, _signals_interrupt():
    try:
        execute(_fake_tasks(), store, workers=2, scheduler=scheduler, runner=run_fake,
                progress=False)
    except KeyboardInterrupt:
        sys.exit(130)
"""


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


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGTERM, signal.SIGINT])
def test_a_killed_or_interrupted_run_leaves_no_process_and_a_consistent_store(
    tmp_path, control, how
):
    (control / "sleep-illumination.k=0-sift-vlad-0").write_text("0")  # its two episodes finish
    (control / "sleep-all").write_text("60")
    env = {**os.environ, "PYTHONPATH": os.getcwd(), CONTROL_ENV: str(control)}
    driver = subprocess.Popen(
        [sys.executable, "-c", _DRIVER, str(tmp_path / "out")], env=env,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 60
    while len(_children(driver.pid)) < 3 and time.monotonic() < deadline:  # 2 workers, tracker
        time.sleep(0.2)
    workers = _children(driver.pid)
    assert len(workers) >= 2, workers
    while not (tmp_path / "out" / "episodes").exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(0.5)
    driver.send_signal(how)
    code = driver.wait(timeout=30)
    assert code == (-signal.SIGKILL if how == signal.SIGKILL else 130), driver.stderr.read()
    deadline = time.monotonic() + 30  # a worker still starting up notices once it has started
    while _alive(workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert _alive(workers) == []
    with ResultStore(tmp_path / "out", "fake") as store:  # the lock is free, the store whole
        done = store.done_keys()
        assert len(done) == 2
        for key in done:
            assert store.read_table(key, "trajectory")["time_s"].shape == (50,)


def test_dask_cluster_on_loopback(tmp_path, control):
    distributed = pytest.importorskip("distributed")
    tasks = _fake_tasks()
    (control / "die-illumination.k=6-sift-vlad-1").touch()
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=None, local_directory=str(tmp_path / "dask"),
    )  # fmt: skip
    with cluster, ResultStore(tmp_path / "out", "fake") as store:
        e = execute(
            tasks, store, scheduler=cluster.scheduler_address, runner=run_fake, progress=False
        )
        assert store.done_keys() == {t.key for t in tasks}
    assert (e.finished, e.errors) == (len(tasks), 0)
    assert e.slots == 2  # the cluster's threads, whatever --workers says
    assert (e.workers_lost, e.retried) == (1, 1)  # the summary says a worker died
    assert not (control / "die-illumination.k=6-sift-vlad-1").exists()  # it did die, once


def test_an_interrupted_dask_run_leaves_the_cluster_idle(tmp_path, control):
    """Dask cannot stop a task that is running, but nothing else of the run may stay queued."""
    distributed = pytest.importorskip("distributed")
    (control / "sleep-all").write_text("2")  # 8 episodes on 2 workers: about 8 s
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
        dashboard_address=None, local_directory=str(tmp_path / "dask"),
    )  # fmt: skip
    env = {**os.environ, "PYTHONPATH": os.getcwd(), CONTROL_ENV: str(control)}
    with cluster, distributed.Client(cluster.scheduler_address) as client:
        driver = subprocess.Popen(
            [sys.executable, "-c", _DRIVER, str(tmp_path / "out"), cluster.scheduler_address],
            env=env, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while not client.processing() or not any(client.processing().values()):
            assert time.monotonic() < deadline, "the run never started"
            time.sleep(0.1)
        driver.send_signal(signal.SIGTERM)
        assert driver.wait(timeout=30) == 130, driver.stderr.read()
        # the episodes in flight finish (2 s); none of the queued ones starts
        deadline = time.monotonic() + 20
        while client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)):
            assert time.monotonic() < deadline, client.processing()
            time.sleep(0.2)
    with ResultStore(tmp_path / "out", "fake") as store:
        assert len(store.done_keys()) < len(_fake_tasks())


def test_an_unreachable_scheduler_is_a_clear_error(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    from vlocbench.bench import runner
    from vlocbench.errors import ConfigError

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 1)
    with ResultStore(tmp_path, "fake") as store, pytest.raises(ConfigError, match="cannot reach"):
        execute(
            _fake_tasks(), store, scheduler="tcp://127.0.0.1:9", runner=run_fake, progress=False
        )


def test_a_grouped_sweep_whose_keys_are_not_sorted_reports_every_cell(tmp_path):
    """The store keeps JSON with sorted keys; the setups it gives back must be the same setups."""
    levels = [{"fog_visual_range_m": v, "rain": 0.8, "overcast": 0.8} for v in (90, 30)]
    spec = load_experiment({"name": "wx", "towns": ["town10"], "methods": ["sift-vlad"],
                            "repetitions": 1, "sweep": {"weather": levels}})  # fmt: skip
    tasks = spec.tasks()
    with ResultStore(tmp_path, "wx") as store:
        store.start_run(spec.spec.spec_hash, to_dict(spec), [t.key for t in tasks])
        execute(tasks, store, workers=1, runner=run_fake, progress=False)
    stored, rows = read_latest_run(tmp_path)
    summary = summarize(plan_from_stored(stored), rows)
    labels = [s.label for s in summary.setups]
    assert labels == [
        "weather(fog_visual_range_m=90, overcast=0.8, rain=0.8)",
        "weather(fog_visual_range_m=30, overcast=0.8, rain=0.8)",
    ]
    for label in labels:
        for method in ("sift-vlad", "odometry"):
            cell = summary.cell("town10", method, label)
            assert cell is not None and cell.failure is not None, (method, label)
        assert summary.cell("town10", "sift-vlad", label).recall is not None


# -- a real experiment end to end: gallery, map, episodes, store, resume, report ------------------
@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny")
    (root / "small.yaml").write_text(yaml.safe_dump(to_dict(small_spec())))
    spec = {
        "name": "tiny",
        "towns": [str(root / "small.yaml")],
        "route_length_m": 60,
        "methods": ["sift-vlad"],
        "sweep": {"illumination.k": [0, 6]},
        "repetitions": 1,
        "baseline_repetitions": 1,  # one odometry drive: the suite stays fast
        "gallery": {"camera": {"intrinsics": {"width": 320, "height": 240}}},
        "output": str(root / "out"),
        "cache": str(root / "cache"),
    }
    (root / "tiny.yaml").write_text(yaml.safe_dump(spec))
    summary = run_experiment(load_experiment(root / "tiny.yaml"), progress=False)
    return root, summary


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
    recall = [r for r in rows if r.kind == "recall"]
    assert len(recall) == 2 and all(r.metrics["queries"] > 10 for r in recall)
    assert all(r.metrics["recall"][3] > 0.5 for r in recall)  # it localizes on its own map
    assert all(r.metrics["place_recall"][-1] > 0.9 for r in recall)  # Recall@10 within 25 m
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
        moved = str(Path(map_dir).parent.with_name("small-0123456789-fedcba9876") / "sift-vlad")
        db.execute(
            "UPDATE episodes SET config = json_set(config, '$.map_dir', ?) WHERE key = ?",
            (moved, key),
        )
    plan = load_experiment(root / "tiny.yaml").with_output(out)
    with pytest.raises(StoreError, match=f"episode {key} .* captured again with other content"):
        run_experiment(plan, progress=False)


def test_galleries_and_maps_made_side_by_side_equal_those_made_in_turn(tiny, tmp_path):
    """Two towns' galleries, then maps, in two pool workers (one thread each): the tiny run's town,
    made in turn in the driver with every thread, comes out the same, image for image and point
    for point."""
    root, _ = tiny
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump(to_dict(small_spec(seed=4))))
    spec.update(towns=[spec["towns"][0], str(other)], cache=str(tmp_path / "cache"))
    maps = prepare_maps(load_experiment(spec), workers=2)
    assert len(maps) == 2 and all((Path(m) / MAP_FILE).exists() for m in maps.values())
    side_by_side = Path(maps[(spec["towns"][0], "sift-vlad")])
    in_turn = root / "cache" / side_by_side.relative_to(tmp_path / "cache")
    images = sorted((root / "cache" / "galleries").glob("*/images/*"))
    assert images
    for image in images:
        twin = tmp_path / "cache" / image.relative_to(root / "cache")
        assert image.read_bytes() == twin.read_bytes(), image.name
    points = [
        sorted(tuple(p.xyz) for p in pycolmap.Reconstruction(m / "sfm").points3D.values())
        for m in (side_by_side, in_turn)
    ]
    assert points[0] and points[0] == points[1]


def test_a_gallery_another_process_is_capturing_is_waited_for(tiny):
    """Not even a finished gallery is read while another process holds its folder."""
    from vlocbench.bench.runner import prepare_gallery

    root, _ = tiny
    plan = load_experiment(root / "tiny.yaml")
    town = plan.spec.towns[0]
    folder = root / "cache" / "galleries" / plan.gallery_folder(town)
    gallery = call_behind_build_lock(folder, lambda: prepare_gallery(plan, town))
    assert gallery.root == folder and len(gallery) > 10


def test_report_of_a_run(tiny):
    from vlocbench.bench.report import write_report

    root, _ = tiny
    files = write_report(root / "out")
    md = files.markdown.read_text()
    assert "| sift-vlad |" in md and "| odometry only |" in md and "k=6" in md
    assert "place recognition alone" in md and "| sift-vlad | 25 m |" in md
    assert "/km) |" in md  # the fused recall with the EKF's lock losses in the ground-truth drive
    assert r"\begin{tabular}" in files.latex.read_text()
    assert {p.name for p in files.figures} == {"failure_rate_small.png", "failure_sites_small.png",
                                               "failure_vs_recall.png", "computation_time.png"}  # fmt: skip
    page = files.html.read_text()
    assert page.count("data:image/png;base64,") == 4
    assert page.count("data:image/jpeg;base64,") == 4  # query and gallery view per setup
    assert 'src="http' not in page  # self-contained


def test_a_run_exports_for_evo_hloc_and_colmap(tiny, capsys):
    """TUM and hloc files of the real run: the errors between their poses are the store's own."""
    import pycolmap

    from vlocbench.bench.store import read_episode_table
    from vlocbench.cli import main
    from vlocbench.geometry import make_pose, pose_error, rotation_from_quaternion

    root, _ = tiny
    out = root / "out"
    for fmt in ("tum", "kitti", "hloc", "colmap"):
        assert main(["export", str(out), "--format", fmt]) == 0
    assert "files to" in capsys.readouterr().out
    assert main(["export", str(out), "--format", "csv"]) == 1
    assert "unknown format 'csv'; valid: colmap, hloc, kitti, tum" in capsys.readouterr().err
    with ResultStore(out, "tiny") as store:
        rows = {r.kind: r for r in store.rows() if r.kind != "failure"}
    recall = rows["recall"].key
    locs = read_episode_table(out, recall, "localizations")
    ok = locs["success"].astype(bool)

    def tum(path):
        a = np.loadtxt(path, ndmin=2)
        return a[:, 0], [make_pose(rotation_from_quaternion(*r[4:8]), r[1:4]) for r in a]

    t_est, est = tum(out / "export" / "tum" / recall / "estimates.txt")
    t_true, true = tum(out / "export" / "tum" / recall / "estimates_truth.txt")
    assert np.array_equal(t_est, locs["time_s"][ok]) and np.array_equal(t_est, t_true)
    errors = np.array([pose_error(a, b) for a, b in zip(true, est, strict=True)])
    assert np.allclose(errors[:, 0], locs["position_error_3d_m"][ok], atol=1e-6)
    assert np.allclose(errors[:, 1], locs["rotation_error_deg"][ok], atol=1e-4)
    truth_rows = len(read_episode_table(out, recall, "trajectory")["time_s"])
    kitti = np.loadtxt(out / "export" / "kitti" / recall / "ekf.txt")
    assert kitti.shape == (truth_rows, 12)
    baseline = out / "export" / "tum" / rows["baseline"].key
    assert sorted(p.name for p in baseline.iterdir()) == ["ekf.txt", "truth.txt"]

    hloc = out / "export" / "hloc" / recall

    def cam_poses(name):
        lines = [x.split() for x in (hloc / name).read_text().splitlines() if x[0] != "#"]
        return {x[0]: make_pose(rotation_from_quaternion(*map(float, (*x[2:5], x[1]))),
                                np.array(x[5:8], float)) for x in lines}  # fmt: skip

    results, truth = cam_poses("results.txt"), cam_poses("ground_truth.txt")
    assert len(results) == ok.sum() and len(truth) == len(ok)
    queries = (hloc / "queries_with_intrinsics.txt").read_text().splitlines()
    assert len(queries) == len(ok) and queries[0].split()[1:4] == ["PINHOLE", "320", "240"]
    for k, name in zip(np.flatnonzero(ok), results, strict=True):  # cam_from_world, COLMAP's
        _, rotation_deg = pose_error(np.linalg.inv(truth[name]), np.linalg.inv(results[name]))
        assert rotation_deg == pytest.approx(locs["rotation_error_deg"][k], abs=1e-4)
    [model] = (out / "export" / "colmap").iterdir()
    assert pycolmap.Reconstruction(model).num_reg_images() > 10


def test_an_episode_as_a_rerun_recording_reads_back(tiny, tmp_path, capsys):
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    from vlocbench.bench.store import read_episode_table
    from vlocbench.cli import main

    root, _ = tiny
    out = root / "out"
    path = tmp_path / "drive.rrd"
    args = ["view", str(out), "--setup", "k=6", "--method", "sift-vlad", "--images"]
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
    assert f'<a href="../view/{row.key}.rrd">' in page and "failure drive, small, sift-vlad" in page


def test_a_run_as_bags_with_its_query_images(tiny, capsys):
    """The recall drive's bag holds every query image, rendered again as the episode saw it, and
    its 6-DoF answers with the covariance the EKF gave them."""
    pytest.importorskip("rosbags")
    import cv2
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from vlocbench.bench.export import estimate_poses
    from vlocbench.bench.replay import QueryRenderer, episode_camera
    from vlocbench.bench.store import read_episode_table
    from vlocbench.cli import main

    root, _ = tiny
    out = root / "out"
    with pytest.raises(SystemExit, match="2"):  # images go into bags only
        main(["export", str(out), "--format", "tum", "--images"])
    assert "add --rosbag" in capsys.readouterr().err
    with ResultStore(out, "tiny") as store:
        [row] = [r for r in store.rows() if r.kind == "recall" and r.setup.endswith("k=6")]
    assert main(["export", str(out), "--rosbag"]) == 0
    assert main(["export", str(out), "--rosbag", "--images"]) == 0  # adds what the bags lacked
    assert "wrote 5 bags" in capsys.readouterr().out.splitlines()[-1]
    locs = read_episode_table(out, row.key, "localizations")
    typestore = get_typestore(Stores.ROS2_KILTED)
    with Reader(out / "bags" / row.key) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        messages = [
            (c.topic, typestore.deserialize_cdr(raw, c.msgtype)) for c, _, raw in reader.messages()
        ]
    cam = episode_camera(row.config).name
    assert (
        counts[f"/{cam}/image/compressed"] == counts[f"/{cam}/camera_info"] == len(locs["time_s"])
    )
    assert not list((out / "bags").glob("*.partial"))
    images = [m for topic, m in messages if topic == f"/{cam}/image/compressed"]
    first = cv2.imdecode(np.asarray(images[0].data, np.uint8), cv2.IMREAD_COLOR)
    with QueryRenderer(row.config) as renderer:
        again, later = (
            renderer.image(locs["true_x_m"][k], locs["true_y_m"][k], locs["true_yaw_rad"][k],
                           float(locs["time_s"][k]))
            for k in (0, 5)
        )  # fmt: skip
    assert first.shape == (240, 320, 3)
    loss = np.abs(first[:, :, ::-1].astype(int) - again).mean()
    assert loss < 6 and np.abs(first[:, :, ::-1].astype(int) - later).mean() > 3 * loss
    info = next(m for topic, m in messages if topic == f"/{cam}/camera_info")
    assert (info.width, info.height) == (320, 240) and info.k[0] > 0
    answered = np.flatnonzero(locs["success"])
    estimates = [m for topic, m in messages if topic == "/visual_pose_estimate"]
    assert len(estimates) == len(answered)
    z_m = estimate_poses(locs, answered)[:, 2, 3]
    assert np.allclose([e.pose.pose.position.z for e in estimates], z_m)
    covariance = np.reshape(estimates[0].pose.covariance, (6, 6))
    assert np.allclose(np.diag(covariance), [0.1, 0.1, 0, 0, 0, 0.1])  # the paper's, x, y, yaw


def test_cli_run_and_report_errors(tiny, tmp_path, capsys):
    from vlocbench.cli import main

    root, _ = tiny
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"towns": ["town10"], "methods": ["sift-vlad"],
                                   "sweep": {"weather.fogg": [10]}}))  # fmt: skip
    assert main(["run", str(bad)]) == 1
    assert "valid: fog_model, fog_ramp_m, fog_visual_range_m, overcast, rain, wetness" in (
        capsys.readouterr().err
    )
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump({"towns": ["town10"], "baseline": True, "recall": False,
                                     "failure": False, "output": str(root / "out")}))  # fmt: skip
    assert main(["run", str(other), "--no-progress"]) == 1
    assert "holds results of experiment 'tiny', not 'other'" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # a malformed command line: usage, 2
        main(["run", str(other), "--workers", "0"])
    assert exc.value.code == 2
    assert "--workers: must be at least 1, got 0" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "empty")]) == 1
    assert "holds no vlocbench results" in capsys.readouterr().err
    assert main(["report", str(root / "out"), "--no-examples"]) == 0
    assert "index.html" in capsys.readouterr().out
    assert os.path.exists(root / "out" / "report" / "tables.md")


def _fake_maps(plan):
    """Map folders named as the runner names them (none is built: the fake episodes need none)."""
    return {
        (t, m.name): f"/nowhere/{plan.gallery_folder(t)}-0123456789/{plan.map_name(m)}"
        for t in plan.spec.towns
        for m in plan.spec.methods
    }


def _run_fake_plans(root, *plans):
    """Run ``plans`` in turn into the store at ``root`` as the runner would."""
    with ResultStore(root, "ill") as store:
        for plan in plans:
            tasks = [t.on_maps(_fake_maps(plan)) for t in plan.tasks()]
            store.start_run(plan.spec.spec_hash, to_dict(plan), [t.key for t in tasks])
            todo = [t for t in tasks if t.key not in store.done_keys()]
            execute(todo, store, workers=1, runner=run_fake, progress=False)


_ILL = {
    "name": "ill",
    "towns": ["town10"],
    "methods": ["sift-vlad"],
    "repetitions": 1,
    "baseline_repetitions": 1,
}


def test_episodes_another_sweep_ran_first_count_under_this_plans_setups(tmp_path):
    """The reduced sweep's k = 0 episodes were first run as a one-level sweep ("default")."""
    first = load_experiment({**_ILL, "sweep": {"illumination.k": [0]}})
    second = load_experiment({**_ILL, "sweep": {"illumination.k": [0, 6]}})
    _run_fake_plans(tmp_path, first, second)
    stored, rows = read_latest_run(tmp_path)
    assert {r.setup for r in rows} == {"default", "illumination.k=6"}  # as each run stored them
    summary = summarize(plan_from_stored(stored), rows)
    for label in ("illumination.k=0", "illumination.k=6"):
        cell = summary.cell("town10", "sift-vlad", label)
        assert cell is not None and cell.failure is not None and cell.recall is not None, label


def test_an_old_runs_report_shows_its_episodes_where_they_were_stored(tmp_path, monkeypatch):
    """A run stored by an earlier EPISODE_VERSION: its keys are none of the plan's now, yet its
    report shows every cell, the baseline under every setup it served."""
    import vlocbench.bench.experiment as experiment

    _run_fake_plans(tmp_path, load_experiment({**_ILL, "sweep": {"illumination.k": [0, 6]}}))
    monkeypatch.setattr(experiment, "EPISODE_VERSION", experiment.EPISODE_VERSION + 1)
    stored, rows = read_latest_run(tmp_path)
    plan = plan_from_stored(stored)
    assert not {t.key for t in plan.tasks()} & {r.key for r in rows}
    summary = summarize(plan, rows)
    for label in ("illumination.k=0", "illumination.k=6"):
        for method in ("sift-vlad", "odometry"):
            cell = summary.cell("town10", method, label)
            assert cell is not None and cell.failure is not None, (method, label)


def test_a_sweep_run_in_parts_is_reported_whole(tmp_path, capsys):
    """A sweep run a level at a time (as on a small machine): the latest run's report shows its
    level, the experiment's report every level; episodes from another gallery do not count."""
    from vlocbench.bench.report import write_report
    from vlocbench.cli import main

    whole = {**_ILL, "sweep": {"illumination.k": [0, 6]}}
    (tmp_path / "ill.yaml").write_text(yaml.safe_dump(whole))
    parts = [load_experiment({**_ILL, "sweep": {"illumination.k": [k]}}) for k in (6, 0)]
    other_gallery = load_experiment({**whole, "gallery": {"spacing_m": 4.0}})
    _run_fake_plans(tmp_path, other_gallery, *parts)
    latest = write_report(tmp_path, examples=False).summary
    assert [s.label for s in latest.setups] == ["default"] and latest.episodes == 3

    plan = load_experiment(tmp_path / "ill.yaml")
    files = write_report(tmp_path, examples=False, plan=plan)
    summary, planned = files.summary, plan.tasks()
    assert summary.episodes == summary.planned == len(planned) == 5  # (recall, failure) x 2, base
    for label in ("illumination.k=0", "illumination.k=6"):
        cell = summary.cell("town10", "sift-vlad", label)
        assert cell is not None and cell.failure is not None and cell.recall is not None, label
        assert cell.keys <= {t.key for t in planned}  # none of the other gallery's
    assert "5 of 5 episodes" in files.html.read_text()

    assert main(["report", str(tmp_path), "--experiment", str(tmp_path / "ill.yaml"),
                 "--no-examples"]) == 0  # fmt: skip
    assert "5 of the 5 episodes of ill" in capsys.readouterr().out
    (tmp_path / "t01.yaml").write_text(yaml.safe_dump({**whole, "towns": ["town01"]}))
    assert main(["report", str(tmp_path), "--experiment", str(tmp_path / "t01.yaml")]) == 1
    assert "holds no episode of experiment 'ill'" in capsys.readouterr().err
