import dataclasses

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from tests.bench.fakes import synthetic_result
from tests.bench.test_store import _row
from vlocbench.bench.store import ResultStore
from vlocbench.cli import main


def test_a_run_exports_as_bags_that_read_back(tmp_path, capsys):
    with ResultStore(tmp_path, "exp") as store:
        store.start_run("r", {"name": "exp"}, ["a", "b"])
        store.write_episode(_row("a"), synthetic_result(1, queries=4))
        store.write_episode(_row("b", "error"), None)
    assert main(["export", str(tmp_path), "--rosbag"]) == 0
    assert "wrote 1 bags" in capsys.readouterr().out
    typestore = get_typestore(Stores.ROS2_KILTED)
    with Reader(tmp_path / "bags" / "a") as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        assert counts == {
            "/ground_truth/odom": 50,
            "/ekf/odom": 50,
            "/wheel_odometry": 50,
            "/visual_pose_estimate": 4,
            "/visual_pose_truth": 4,
        }
        wheel = next(
            typestore.deserialize_cdr(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == "/wheel_odometry"
        )
        assert wheel.twist.twist.linear.x == pytest.approx(4.1)
        assert wheel.twist.covariance[0] == pytest.approx((0.04 * 4.1) ** 2)  # the paper's model
        estimates = [
            (t, typestore.deserialize_cdr(raw, c.msgtype))
            for c, t, raw in reader.messages()
            if c.topic == "/visual_pose_estimate"
        ]
    t_ns, first = estimates[0]
    assert first.header.frame_id == "map" and first.pose.pose.position.x == pytest.approx(0.1)
    assert t_ns == pytest.approx(0.2e9)  # written when it reached the EKF, after its latency
    assert (first.header.stamp.sec, first.header.stamp.nanosec) == (0, 0)  # its image's time
    assert np.allclose(np.reshape(first.pose.covariance, (6, 6)), np.diag([0.1, 0.1, 0, 0, 0, 0.1]))
    assert main(["export", str(tmp_path), "--rosbag"]) == 0  # bags already there are kept
    assert "wrote 0 bags" in capsys.readouterr().out
    assert main(["export", str(tmp_path / "none"), "--rosbag"]) == 1
    assert "holds no vlocbench results" in capsys.readouterr().err


def test_an_answer_with_its_own_covariance_carries_it_into_the_bag(tmp_path):
    """A plugin localizer's covariance is what the EKF got, so the bag gives it; an answer
    without one gets the EKF's default."""
    result = synthetic_result(0, queries=2)
    own = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.002], [0.0, 0.002, 0.0025]])
    first = dataclasses.replace(result.localizations[0], covariance=tuple(own.ravel()))
    result = dataclasses.replace(result, localizations=(first, *result.localizations[1:]))
    with ResultStore(tmp_path, "exp") as store:
        store.start_run("r", {"name": "exp"}, ["a"])
        store.write_episode(_row("a"), result)
    assert main(["export", str(tmp_path), "--rosbag"]) == 0
    typestore = get_typestore(Stores.ROS2_KILTED)
    with Reader(tmp_path / "bags" / "a") as reader:
        covariances = [
            np.reshape(typestore.deserialize_cdr(raw, c.msgtype).pose.covariance, (6, 6))
            for c, _, raw in reader.messages()
            if c.topic == "/visual_pose_estimate"
        ]
    assert np.allclose(covariances[0][np.ix_([0, 1, 5], [0, 1, 5])], own)
    assert np.allclose(covariances[0][2:5], 0) and np.allclose(covariances[0][:, 2:5], 0)
    assert np.allclose(covariances[1], np.diag([0.1, 0.1, 0, 0, 0, 0.1]))


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
            renderer.image(
                locs["true_x_m"][k],
                locs["true_y_m"][k],
                locs["true_yaw_rad"][k],
                float(locs["time_s"][k]),
            )
            for k in (0, 5)
        )
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
