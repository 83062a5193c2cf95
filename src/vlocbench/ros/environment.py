"""The ROS 2 environment a vlocbench node starts in."""

from __future__ import annotations

import os
import tempfile
from collections.abc import MutableMapping


def local_only(env: MutableMapping[str, str] | None = None) -> MutableMapping[str, str]:
    """Keep DDS discovery on this machine and ROS logs in a temporary folder, unless the user set
    them: ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (else ``LOCALHOST``) and ``ROS_LOG_DIR``. Call it
    before ``rclpy.init``; returns ``env`` (``os.environ`` by default)."""
    env = os.environ if env is None else env
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env.setdefault("ROS_LOG_DIR", tempfile.mkdtemp(prefix="vlocbench-ros-log-"))
    return env
