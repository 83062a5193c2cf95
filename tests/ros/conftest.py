"""ROS 2 fixtures: a private domain per test process, discovery on loopback only, logs in tmp."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy")


ROS_DOMAINS = range(30, 102)  # ROS 2's portable range is 0-101; 0, the default, stays free


def domain_lock(domain: int) -> Path:
    """The file whose exclusive lock holds ``domain`` for one test process."""
    return Path(tempfile.gettempdir()) / f"vlocbench-ros-domain-{domain}.lock"


@pytest.fixture(scope="session")
def ros_domain() -> Iterator[int]:
    """A ROS domain that no other test process on this machine holds while this one runs: nodes of
    one domain hear each other, and two runs at once (pytest -n 2's workers, or another
    checkout's tests) otherwise answer each other's queries."""
    for domain in ROS_DOMAINS:
        with open(domain_lock(domain), "w") as lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue
            yield domain  # held until the session ends and the file closes
            return
    pytest.fail(f"every ROS domain of {ROS_DOMAINS} is held by another test process")


@pytest.fixture
def ros_env(monkeypatch, tmp_path, ros_domain):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_LOG_DIR", str(tmp_path / "ros-log"))
    monkeypatch.setenv("ROS_DOMAIN_ID", str(ros_domain))
    return {"ROS_DOMAIN_ID": str(ros_domain)}


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
