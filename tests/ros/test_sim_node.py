import os
import signal
import subprocess
import sys

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import Twist, TwistWithCovarianceStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image

from tests.conftest import assert_stops_cleanly, small_spec
from tests.ros.conftest import spin_until
from vlocbench.config import to_dict
from vlocbench.errors import ConfigError
from vlocbench.ros.sim_node import SimulatorNode, load_world


@pytest.fixture
def world(tmp_path):
    town = tmp_path / "small.yaml"
    town.write_text(yaml.safe_dump(to_dict(small_spec())))
    config = tmp_path / "world.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "conditions": {"illumination": {"k": 2}},
                "cameras": [{"name": "right", "intrinsics": {"width": 160, "height": 120}}],
            }
        )
    )
    return str(town), config


def test_the_sim_node_drives_on_cmd_vel_and_publishes_its_world(ros_context, world):
    sim = SimulatorNode(
        *world, context=ros_context, parameter_overrides=[Parameter("real_time_factor", value=0.0)]
    )
    probe = Node("probe", context=ros_context)
    got = {"clock": [], "truth": [], "wheel": [], "image": [], "info": [], "route": []}
    probe.create_subscription(Clock, "/clock", got["clock"].append, 10)
    probe.create_subscription(Odometry, "ground_truth/odom", got["truth"].append, 10)
    probe.create_subscription(TwistWithCovarianceStamped, "wheel_odometry", got["wheel"].append, 10)
    probe.create_subscription(Image, "right/image", got["image"].append, 10)
    probe.create_subscription(CameraInfo, "right/camera_info", got["info"].append, 10)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    probe.create_subscription(PathMsg, "route", got["route"].append, latched)
    cmd = probe.create_publisher(Twist, "cmd_vel", 10)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    executor.add_node(probe)
    spin_until(executor, lambda: cmd.get_subscription_count() > 0)
    command = Twist()
    command.linear.x = 3.0
    cmd.publish(command)

    def clock_s():
        return (
            got["clock"][-1].clock.sec + got["clock"][-1].clock.nanosec * 1e-9
            if got["clock"]
            else 0
        )

    spin_until(executor, lambda: clock_s() >= 6.0, 120)
    truth = got["truth"][-1]
    assert 1.5 < truth.twist.twist.linear.x < 4.5  # the speed PID follows cmd_vel
    start = got["truth"][0].pose.pose.position
    moved = np.hypot(truth.pose.pose.position.x - start.x, truth.pose.pose.position.y - start.y)
    assert moved > 5.0
    wheel = got["wheel"][-1].twist
    assert wheel.covariance[0] == pytest.approx((0.04 * truth.twist.twist.linear.x) ** 2, rel=0.05)
    assert wheel.twist.linear.x != truth.twist.twist.linear.x  # noisy, as the paper's model
    # 2 Hz of simulated time: an image every 0.5 s, stamped like the clock
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in got["image"]]
    assert len(stamps) >= 10 and np.allclose(np.diff(stamps)[:10], 0.5, atol=1e-6)
    assert (got["image"][0].width, got["image"][0].height) == (160, 120)
    assert got["info"][0].k[0] == pytest.approx(80.0)  # 160 px over 90 deg
    assert got["route"] and len(got["route"][0].poses) > 50
    sim.destroy_node()


def test_a_bad_world_file_names_the_field(world, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("conditions: {illumination: {k: 12}}\n")
    with pytest.raises(ConfigError, match=r"illumination\.k: must be in \[0, 10\]"):
        load_world(world[0], bad)
    bad.write_text("lights: on\n")
    with pytest.raises(
        ConfigError, match="unknown keys \\['lights'\\]; valid: cameras, conditions"
    ):
        load_world(world[0], bad)


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
def test_the_cli_sim_node_stops_cleanly(ros_context, ros_env, world, stop):
    """`vlocbench ros sim` from its own process, once it publishes images (the renderer and the
    native libraries loaded): both signals end it with 0 and no native stack trace."""
    town, config = world
    proc = subprocess.Popen(
        [sys.executable, "-m", "vlocbench.cli", "ros", "sim", town, "--config", str(config)],
        env={**os.environ, **ros_env},
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        probe = Node("probe", context=ros_context)
        images = []
        probe.create_subscription(Image, "right/image", images.append, 10)
        executor = SingleThreadedExecutor(context=ros_context)
        executor.add_node(probe)
        spin_until(executor, lambda: images, 60)
    finally:
        assert_stops_cleanly(proc, stop, 0)
