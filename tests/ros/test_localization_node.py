import signal

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image

from tests.conftest import CAMERA, assert_stops_cleanly
from tests.ros.conftest import spin_until, start_localize_node
from vlocbench.bench.visual import camera_model
from vlocbench.errors import UnknownNameError
from vlocbench.geometry import pose_error
from vlocbench.ros.localization_node import LocalizationNode
from vlocbench.ros.messages import info_from_camera, msg_from_image, pose_from_msg


class _Tester(Node):
    """Publishes images and camera info; collects poses and statuses."""

    def __init__(self, context):
        super().__init__("tester", context=context)
        self.image_pub = self.create_publisher(Image, "image", 10)
        self.info_pub = self.create_publisher(CameraInfo, "camera_info", 10)
        self.poses, self.statuses = [], []
        self.create_subscription(
            PoseWithCovarianceStamped, "visual_pose_estimate", self.poses.append, 10
        )
        self.create_subscription(
            DiagnosticArray, "diagnostics", lambda m: self.statuses.extend(m.status), 10
        )

    def values(self, status):
        return {kv.key: kv.value for kv in status.values}


@pytest.fixture
def query(small_sim, stretch):
    """A camera image between two gallery images, with the true vehicle pose."""
    x, y = (stretch.xy[10] + stretch.xy[11]) / 2
    small_sim.teleport(float(x), float(y), float(stretch.yaw_rad[10]) + 0.02)
    frame = small_sim.render([CAMERA], frame_id=0)[0]  # not the shared simulator's clock
    return frame.image, frame.world_from_cam @ np.linalg.inv(CAMERA.extrinsics.vehicle_from_cam())


def _nodes(context, map_dir, **params):
    overrides = [Parameter("map_dir", value=str(map_dir))]
    overrides += [Parameter(k, value=v) for k, v in params.items()]
    node = LocalizationNode(context=context, parameter_overrides=overrides)
    tester = _Tester(context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(tester)
    return node, tester, executor


def test_an_image_comes_back_as_the_vehicle_pose(ros_context, sift_map, query):
    image, world_from_vehicle = query
    node, tester, executor = _nodes(ros_context, sift_map[0], localization_frequence=10.0)
    stamp = Time(sec=12, nanosec=500)
    tester.info_pub.publish(info_from_camera(camera_model(CAMERA), stamp, "camera"))
    spin_until(executor, lambda: node.camera_info is not None)
    tester.image_pub.publish(msg_from_image(image, stamp, "camera"))
    spin_until(executor, lambda: tester.poses)
    pose = tester.poses[0]
    assert pose.header.frame_id == "map" and pose.header.stamp == stamp  # the image's time
    position_m, rotation_deg = pose_error(world_from_vehicle, pose_from_msg(pose.pose.pose))
    assert position_m <= 0.25 and rotation_deg <= 2.0
    covariance = np.reshape(pose.pose.covariance, (6, 6))  # the PnP's, for 1 px of noise
    assert np.allclose(covariance, covariance.T) and np.all(np.linalg.eigvalsh(covariance) > 0)
    assert 1e-3 < np.sqrt(covariance[0, 0]) < 0.5 and np.sqrt(covariance[5, 5]) < np.radians(2)
    spin_until(executor, lambda: tester.statuses)
    status = tester.values(tester.statuses[-1])
    assert status["state"] == "localized" and int(status["inliers"]) >= 20
    assert float(status["computation_time_s"]) > 0
    node.destroy_node()


def test_the_papers_fixed_covariance_is_an_option(ros_context, sift_map, query):
    image, _ = query
    node, tester, executor = _nodes(
        ros_context, sift_map[0], localization_frequence=10.0, covariance="fixed"
    )
    tester.image_pub.publish(msg_from_image(image, Time(sec=1), "camera"))
    spin_until(executor, lambda: tester.poses)
    assert np.allclose(np.reshape(tester.poses[0].pose.covariance, (6, 6)), np.eye(6) * 0.1)
    node.destroy_node()
    with pytest.raises(UnknownNameError, match="valid: estimate, fixed"):
        _nodes(ros_context, sift_map[0], covariance="pnp")


def test_bad_images_are_reported_and_the_node_lives_on(ros_context, sift_map, query):
    image, _ = query
    node, tester, executor = _nodes(ros_context, sift_map[0], localization_frequence=10.0)
    stamp = Time(sec=1)
    bad = msg_from_image(image, stamp, "camera")
    bad.encoding = "bgr16"
    tester.image_pub.publish(bad)
    spin_until(executor, lambda: tester.statuses)
    assert "encoding 'bgr16' is not supported" in tester.statuses[-1].message
    assert tester.statuses[-1].level == b"\x02"  # ERROR
    tester.image_pub.publish(msg_from_image(image[::2, ::2].copy(), stamp, "camera"))
    spin_until(executor, lambda: len(tester.statuses) >= 2)
    assert "the image is 160x120, its camera 320x240" in tester.statuses[-1].message
    tester.image_pub.publish(msg_from_image(image, stamp, "camera"))  # and it still localizes
    spin_until(executor, lambda: tester.poses)
    node.destroy_node()


def test_a_map_that_does_not_load_is_a_status_not_a_dead_node(ros_context, tmp_path):
    node, tester, executor = _nodes(ros_context, tmp_path / "nowhere", localization_frequence=10.0)
    spin_until(executor, lambda: tester.statuses)
    status = tester.statuses[-1]
    assert status.level == b"\x02" and "does not load" in status.message
    assert "is not a map (no map.json)" in status.message
    node.destroy_node()


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_the_cli_node_answers_from_its_own_process_and_stops_cleanly(
    ros_context, ros_env, sift_map, query, stop
):
    """A container stop, systemd or a launch system sends SIGTERM: after the node has answered
    (its native libraries loaded), both signals end it with 0 and no native stack trace."""

    image, world_from_vehicle = query
    proc = start_localize_node(sift_map[0], ros_env, localization_frequence=5.0, camera_topic="cam")
    try:
        tester = _Tester(ros_context)
        cam_pub = tester.create_publisher(Image, "cam", 10)
        executor = SingleThreadedExecutor(context=ros_context)
        executor.add_node(tester)
        stamp = Time(sec=3)
        spin_until(executor, lambda: cam_pub.get_subscription_count() > 0, 60)
        tester.info_pub.publish(info_from_camera(camera_model(CAMERA), stamp, "camera"))
        cam_pub.publish(msg_from_image(image, stamp, "camera"))
        spin_until(executor, lambda: tester.poses, 60)
        position_m, rotation_deg = pose_error(
            world_from_vehicle, pose_from_msg(tester.poses[0].pose.pose)
        )
        assert position_m <= 0.25 and rotation_deg <= 2.0
    finally:
        assert_stops_cleanly(proc, stop, 0)
