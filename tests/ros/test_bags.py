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
        assert counts == {"/ground_truth/odom": 50, "/ekf/odom": 50, "/wheel_odometry": 50,
                          "/visual_pose_estimate": 4, "/visual_pose_truth": 4}  # fmt: skip
        wheel = next(typestore.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()
                     if c.topic == "/wheel_odometry")  # fmt: skip
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
