"""The simulator as a ROS 2 world (what carla-ros-bridge is for CARLA, synchronous): a user's
ROS 2 navigation stack can drive vlocbench's towns.

Every step (0.05 s of simulated time) the node publishes ``/clock``; ``ground_truth/odom``
(``nav_msgs/Odometry``, the true pose and speed); ``wheel_odometry``
(``geometry_msgs/TwistWithCovarianceStamped``, the speed and yaw rate with the paper's noise model
and its variances); ``collisions`` (``std_msgs/String``) when a contact starts. At
``camera_rate_hz`` each camera publishes ``NAME/image`` and ``NAME/camera_info``; ``route``
(``nav_msgs/Path``, latched) once. The car follows ``cmd_vel`` (``geometry_msgs/Twist``: forward
speed and yaw rate, through the paper's speed PID and the bicycle model's steering) or, when one
arrives, a raw ``control`` (``std_msgs/Float64MultiArray``: throttle, steer, brake). Steps run at
``real_time_factor`` times real time (0: as fast as the machine goes).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from geometry_msgs.msg import PoseStamped, Twist, TwistWithCovarianceStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Float64MultiArray, String

from vlocbench.bench.visual import camera_model
from vlocbench.config import from_dict, load_yaml
from vlocbench.errors import ConfigError
from vlocbench.geometry import planar_pose
from vlocbench.interfaces import Control
from vlocbench.nav import ControllerConfig, OdometryNoise, Pid, WheelOdometry
from vlocbench.nav.control import MPS_TO_KMH
from vlocbench.ros.messages import info_from_camera, msg_from_image, pose_to_msg, stamp_of
from vlocbench.sim import Camera, Conditions, Simulator, gallery_camera
from vlocbench.sim.town import generate_town, load_town_spec

PARAMETERS: dict[str, tuple[Any, str]] = {
    "camera_rate_hz": (2.0, "images per second of every camera (simulated time)"),
    "real_time_factor": (1.0, "simulated seconds per wall second; 0: as fast as possible"),
    "seed": (0, "seed of the wheel odometry's noise"),
}


def load_world(town: str, config: str | Path | None) -> tuple[Any, Conditions, tuple[Camera, ...]]:
    """The town, and the conditions and cameras of ``config`` (a YAML with ``conditions`` and
    ``cameras`` as an experiment writes them; default: noon and the paper's camera)."""
    data = load_yaml(config) if config else {}
    if not isinstance(data, dict):
        raise ConfigError(str(config), "expected a mapping with conditions and cameras")
    unknown = set(data) - {"conditions", "cameras"}
    if unknown:
        raise ConfigError(
            str(config), f"unknown keys {sorted(unknown)}; valid: cameras, conditions"
        )
    conditions = from_dict(Conditions, data.get("conditions") or {}, "conditions")
    cameras = tuple(
        from_dict(Camera, c, f"cameras[{k}]") for k, c in enumerate(data.get("cameras") or [])
    ) or (gallery_camera(),)
    return generate_town(load_town_spec(town)), conditions, cameras


class SimulatorNode(Node):
    """See the module docstring."""

    def __init__(self, town: str, config: str | Path | None = None, **kwargs: Any) -> None:
        super().__init__("vlocbench_sim", **kwargs)
        for name, (default, description) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=description))
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        world, conditions, self.cameras = load_world(town, config)
        self.sim = Simulator(world, conditions)
        self.odometry = WheelOdometry(OdometryNoise(), int(p["seed"]))
        self.speed_pid = Pid(ControllerConfig().longitudinal, self.sim.dt_s)
        self.camera_period_s = 1.0 / float(p["camera_rate_hz"])
        self.next_image_s = 0.0
        self.command: Twist | None = None
        self.raw: Control | None = None
        self.clock_pub = self.create_publisher(Clock, "/clock", 10)
        self.truth_pub = self.create_publisher(Odometry, "ground_truth/odom", 10)
        self.wheel_pub = self.create_publisher(TwistWithCovarianceStamped, "wheel_odometry", 10)
        self.collision_pub = self.create_publisher(String, "collisions", 10)
        self.camera_pubs = {
            cam.name: (
                self.create_publisher(Image, f"{cam.name}/image", 10),
                self.create_publisher(CameraInfo, f"{cam.name}/camera_info", 10),
            )
            for cam in self.cameras
        }
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_publisher(PathMsg, "route", latched).publish(self._route())
        self.create_subscription(Twist, "cmd_vel", self._on_cmd_vel, 10)
        self.create_subscription(Float64MultiArray, "control", self._on_control, 10)
        rate = float(p["real_time_factor"])
        self.create_timer(self.sim.dt_s / rate if rate > 0 else 0.0, self.step)

    def _on_cmd_vel(self, msg: Twist) -> None:
        self.command, self.raw = msg, None

    def _on_control(self, msg: Float64MultiArray) -> None:
        try:
            throttle, steer, brake = (float(v) for v in msg.data)
            self.raw = Control(throttle, steer, brake)
        except (ValueError, ConfigError) as exc:
            self.get_logger().error(f"control: expected [throttle, steer, brake] in range: {exc}")

    def _control(self) -> Control:
        """The raw command, or cmd_vel's speed (the paper's speed PID) and yaw rate (steering of
        the bicycle model at the car's speed)."""
        if self.raw is not None:
            return self.raw
        state, params = self.sim.state, self.sim.params
        speed = self.command.linear.x if self.command else 0.0
        yaw_rate = self.command.angular.z if self.command else 0.0
        accel = self.speed_pid.step((max(speed, 0.0) - state.speed_mps) * MPS_TO_KMH)
        steer_rad = math.atan(params.wheelbase_m * yaw_rate / max(state.speed_mps, 0.5))
        steer = max(-1.0, min(1.0, steer_rad / math.radians(params.max_steer_deg)))
        return Control(max(accel, 0.0), steer, min(-accel, 1.0) if accel < 0 else 0.0)

    def step(self) -> None:
        """One simulation step and what it publishes."""
        before = self.sim.state
        if before.time_s >= self.next_image_s - 1e-9:
            self._publish_images()
            self.next_image_s += self.camera_period_s
        result = self.sim.step(self._control())
        s, stamp = result.state, stamp_of(result.state.time_s)
        self.clock_pub.publish(Clock(clock=stamp))
        truth = Odometry(child_frame_id="base_link")
        truth.header.stamp, truth.header.frame_id = stamp, "map"
        truth.pose.pose = pose_to_msg(s.world_from_vehicle())
        truth.twist.twist.linear.x, truth.twist.twist.angular.z = s.speed_mps, s.yaw_rate_radps
        self.truth_pub.publish(truth)
        reading = self.odometry.read(s.speed_mps, s.yaw_rate_radps)
        wheel = TwistWithCovarianceStamped()
        wheel.header.stamp, wheel.header.frame_id = stamp, "base_link"
        wheel.twist.twist.linear.x = reading.speed_mps
        wheel.twist.twist.angular.z = reading.yaw_rate_radps
        covariance = [0.0] * 36
        covariance[0], covariance[35] = reading.speed_var, reading.yaw_rate_var
        wheel.twist.covariance = covariance
        self.wheel_pub.publish(wheel)
        for e in result.collisions:
            self.collision_pub.publish(
                String(
                    data=f"{e.category} {e.label} at ({e.x_m:.2f}, {e.y_m:.2f}) t={e.time_s:.2f}"
                )
            )

    def _publish_images(self) -> None:
        stamp = stamp_of(self.sim.state.time_s)
        for frame in self.sim.render(self.cameras):
            image_pub, info_pub = self.camera_pubs[frame.camera.name]
            info_pub.publish(info_from_camera(camera_model(frame.camera), stamp, frame.camera.name))
            image_pub.publish(msg_from_image(frame.image, stamp, frame.camera.name))

    def _route(self) -> PathMsg:
        route = self.sim.town.route
        path = PathMsg()
        path.header.frame_id = "map"
        for (x, y), yaw in zip(route.waypoints_xy, route.yaw_rad):
            pose = PoseStamped()
            pose.header.frame_id = "map"
            pose.pose = pose_to_msg(planar_pose(float(x), float(y), float(yaw)))
            path.poses.append(pose)
        return path

    def destroy_node(self) -> None:
        self.sim.close()
        super().destroy_node()
