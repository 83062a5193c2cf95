"""ROS 2 fixtures: a private domain per test worker, discovery on loopback only, logs in tmp."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")


def domain_id(worker_id: str) -> int:
    """A ROS domain of this test worker's own (pytest-xdist runs workers in parallel)."""
    return 60 + (int(worker_id[2:]) if worker_id.startswith("gw") else 20)


@pytest.fixture
def ros_env(monkeypatch, tmp_path, worker_id):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros-log"))
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id(worker_id)))
    return {"ROS_DOMAIN_ID": str(domain_id(worker_id))}


@pytest.fixture
def ros_context(ros_env):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    yield context
    context.try_shutdown()


def spin_until(executor, condition, timeout_s: float = 30.0) -> None:
    """Spin ``executor`` until ``condition()`` holds; fail after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out waiting on ROS"
        executor.spin_once(timeout_sec=0.05)


def start_localize_node(
    map_dir: Path, ros_env: dict[str, str], **params: object
) -> subprocess.Popen[str]:
    """``vlocbench ros localize`` on ``map_dir`` in its own process, with the ROS parameters
    ``params``; its stderr is piped, for the test to show when the node does not stop cleanly."""
    ros_args = [arg for key, value in params.items() for arg in ("-p", f"{key}:={value}")]
    return subprocess.Popen(
        [sys.executable, "-m", "vlocbench.cli", "ros", "localize", "--map", str(map_dir)]
        + (["--ros-args", *ros_args] if ros_args else []),
        env={**os.environ, **ros_env},
        stderr=subprocess.PIPE,
        text=True,
    )
