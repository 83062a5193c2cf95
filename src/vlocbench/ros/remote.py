"""Any ROS 2 localization node as a benchmark method: a :class:`~vlocbench.bench.Localizer` that
sends each query image to the node and waits for its answer.

The episode waits (it stays synchronous, so a drive is as deterministic as the node); the image is
stamped with the episode's simulated time and the answer is the pose stamped alike. Our own node
(``vlocbench ros localize``) reports every attempt on ``diagnostics`` with the image's stamp: a
failure and its reason, and the inliers of a pose (kept with the answer, as in process). For a node
that stays silent on failure, ``timeout_s`` ends the wait.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from vlocbench.bench.localizer import LocalizationQuery, PoseEstimate
from vlocbench.bench.methods import MethodContext, RosEndpoint
from vlocbench.bench.visual import camera_model
from vlocbench.errors import ConfigError
from vlocbench.ros.environment import local_only
from vlocbench.ros.messages import (
    info_from_camera,
    msg_from_image,
    pose_from_msg,
    stamp_key,
    stamp_of,
)
from vlocbench.sim import Camera

STATUS_GRACE_S = 1.0  # how long the first pose waits for a status that may never come


class RosLocalizer:
    """Localizes through the node at ``endpoint``; one camera (the node's)."""

    uses_ground_truth = False

    def __init__(self, endpoint: RosEndpoint, cameras: Sequence[Camera], name: str) -> None:
        if len(cameras) != 1:
            raise ConfigError(f"methods.{name}", f"a ROS node takes one camera, not {len(cameras)}")
        local_only()
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from sensor_msgs.msg import CameraInfo, Image

        self.name, self.endpoint, self._cameras = name, endpoint, tuple(cameras)
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node("vlocbench_episode", context=self.context)
        self.image_pub = self.node.create_publisher(Image, endpoint.image_topic, 10)
        self.info_pub = self.node.create_publisher(CameraInfo, endpoint.camera_info_topic, 10)
        self.poses: dict[str, Any] = {}
        self.failures: dict[str, str] = {}
        self.inliers: dict[str, int] = {}
        # whether the node reports inliers (None: not known before its first pose)
        self._reports_inliers: bool | None = None
        self.node.create_subscription(
            PoseWithCovarianceStamped, endpoint.pose_topic, self._on_pose, 10
        )
        self.node.create_subscription(DiagnosticArray, "diagnostics", self._on_status, 10)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    @property
    def cameras(self) -> Sequence[Camera]:
        return self._cameras

    def _on_pose(self, msg: Any) -> None:
        self.poses[stamp_key(msg.header.stamp)] = msg

    def _on_status(self, msg: Any) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if "stamp" not in values:
                continue
            if values.get("state") != "localized":
                self.failures[values["stamp"]] = status.message
            elif "inliers" in values:
                self.inliers[values["stamp"]] = int(values["inliers"])
                self._reports_inliers = True

    def reset(self, seed: int) -> None:
        self.poses.clear()
        self.failures.clear()
        self.inliers.clear()

    def _wait_for_node(self) -> None:
        deadline = time.monotonic() + self.endpoint.timeout_s
        while self.image_pub.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                raise ConfigError(
                    f"methods.{self.name}.args.image_topic",
                    f"no node subscribes to {self.endpoint.image_topic!r} "
                    f"after {self.endpoint.timeout_s:g} s",
                )
            self.executor.spin_once(timeout_sec=0.05)

    def localize(self, query: LocalizationQuery) -> PoseEstimate:
        self._wait_for_node()
        start = time.perf_counter()
        stamp = stamp_of(query.time_s)
        key = stamp_key(stamp)
        frame = query.frames[0]
        self.info_pub.publish(
            info_from_camera(camera_model(frame.camera), stamp, frame.camera.name)
        )
        self.image_pub.publish(msg_from_image(frame.image, stamp, frame.camera.name))
        deadline = time.monotonic() + self.endpoint.timeout_s
        while key not in self.poses and key not in self.failures:
            if time.monotonic() > deadline:
                return PoseEstimate.failure(
                    f"no answer from {self.endpoint.pose_topic!r} within "
                    f"{self.endpoint.timeout_s:g} s",
                    time.perf_counter() - start,
                )
            self.executor.spin_once(timeout_sec=0.01)
        elapsed = time.perf_counter() - start
        if key in self.poses:
            self._wait_for_inliers(key, deadline)
            msg = self.poses.pop(key)
            inliers = self.inliers.pop(key, 0)
            return PoseEstimate(True, pose_from_msg(msg.pose.pose), None, elapsed, inliers=inliers)
        return PoseEstimate.failure(self.failures.pop(key), elapsed)

    def _wait_for_inliers(self, key: str, deadline: float) -> None:
        """Our node publishes a pose, then its status with the inliers: wait for that status
        (only STATUS_GRACE_S after the first pose, from a node that may send none)."""
        if self._reports_inliers is False:
            return
        if self._reports_inliers is None:
            deadline = min(deadline, time.monotonic() + STATUS_GRACE_S)
        while key not in self.inliers and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)
        if self._reports_inliers is None:  # no status with inliers came (_on_status sets True)
            self._reports_inliers = False

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.context.try_shutdown()


def ros_localizer(context: MethodContext, endpoint: RosEndpoint) -> RosLocalizer:
    """The ``ros`` kind of :data:`~vlocbench.bench.methods.LOCALIZER_KINDS`."""
    return RosLocalizer(endpoint, context.cameras, context.name)
