"""The paper's visual localization node (``visual_localization_node`` of
lasuomela/visual_robot_localization) on vlocbench's hierarchical localizer.

Its parameters keep the paper's names and defaults where they apply; ``map_dir`` replaces the
paper's four file paths. The latest image is localized at ``localization_frequence`` (ROS time, so
``use_sim_time`` works), and the answer is stamped with the image's time:

- ``pose_publish_topic`` (``geometry_msgs/PoseWithCovarianceStamped``, frame ``map``): the pose of
  ``base_frame`` (the camera's, when ``compensate_sensor_offset`` is false) on success, ready for
  robot_localization's ``pose0``, with the PnP's covariance for ``pixel_noise_px`` of image noise
  (x, y, z, then the rotation about the map's axes, which is roll, pitch, yaw near level) or, with
  ``covariance:=fixed``, the paper's (``pose_variance`` on the diagonal);
- ``diagnostics`` (``diagnostic_msgs/DiagnosticArray``): after every attempt, the state, success,
  inliers, computation time and the reason of a failure, in place of the paper's custom messages
  (which cannot be built from pip);
- with ``visualize_estimates``, ``~/retrieved`` (``visualization_msgs/MarkerArray``): the gallery
  images retrieval chose.

tf2 does not install from pip, so the camera's mounting on the base is the ``sensor_offset``
parameter (x, y, z in metres, roll, pitch, yaw in degrees; default: the paper's right-facing
camera). Bad input (an encoding, a size against the camera info, an empty image, a map that does
not load) is logged and reported on ``diagnostics``; the node lives on.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseWithCovarianceStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo
from sensor_msgs.msg import Image as ImageMsg
from visualization_msgs.msg import Marker, MarkerArray

from vlocbench.config import require_one_of
from vlocbench.errors import VlocbenchError
from vlocbench.geometry import invert_pose
from vlocbench.loc.gallery import CameraModel, Gallery
from vlocbench.loc.localizer import COVARIANCES, LocalizerConfig, MapLocalizer, QueryResult
from vlocbench.loc.mapping import MAP_FILE
from vlocbench.loc.registry import method_conf
from vlocbench.ros.messages import (
    camera_from_info,
    image_from_msg,
    pose_from_msg,
    pose_to_msg,
    pose_with_covariance,
    stamp_key,
)
from vlocbench.sim.camera import Extrinsics

PAPER_SENSOR_OFFSET = dataclasses.astuple(Extrinsics())  # the paper's gallery camera's mounting

# name: (default, description); the paper's names first
PARAMETERS: dict[str, tuple[Any, str]] = {
    "camera_topic": ("image", "sensor_msgs/Image to localize (rgb8, bgr8 or mono8)"),
    "pose_publish_topic": ("visual_pose_estimate", "PoseWithCovarianceStamped out, frame map"),
    "localization_frequence": (2.0, "localizations per second (ROS time)"),
    "top_k_matches": (5, "gallery images retrieved per query"),
    "ransac_thresh": (12.0, "PnP RANSAC reprojection threshold, pixels"),
    "base_frame": ("base_link", "frame of the published pose when compensating the offset"),
    "sensor_frame": ("camera", "frame of the camera"),
    "compensate_sensor_offset": (True, "publish the base's pose, not the camera's"),
    "visualize_estimates": (False, "publish the retrieved gallery images as markers"),
    "map_dir": ("", "map folder (vlocbench build-map)"),
    "method": ("", "expected localization method; empty: whatever the map was built with"),
    "camera_info_topic": ("camera_info", "CameraInfo of the images; else the map's camera"),
    "prior_topic": ("", "PoseWithCovarianceStamped prior (pose-prior maps such as sift-prior)"),
    "sensor_offset": (
        list(PAPER_SENSOR_OFFSET),
        "base_from_sensor: x, y, z m, roll, pitch, yaw deg",
    ),
    "covariance": ("estimate", "published covariance: estimate (the PnP's) or fixed (the paper's)"),
    "pixel_noise_px": (1.0, "image noise the PnP's covariance assumes (covariance: estimate)"),
    "pose_variance": (0.1, "diagonal of the covariance when fixed (the paper's 0.1)"),
}


class LocalizationNode(Node):
    """See the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("visual_localization_node", **kwargs)
        for name, (default, description) in PARAMETERS.items():
            self.declare_parameter(name, default, ParameterDescriptor(description=description))
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self.params = p
        require_one_of(p["covariance"], COVARIANCES, "covariance")
        self.base_from_sensor = Extrinsics(*map(float, p["sensor_offset"])).vehicle_from_cam()
        self.pose_pub = self.create_publisher(
            PoseWithCovarianceStamped, p["pose_publish_topic"], 10
        )
        self.status_pub = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.marker_pub = (
            self.create_publisher(MarkerArray, "~/retrieved", 10)
            if p["visualize_estimates"]
            else None
        )
        self.lock = threading.Lock()
        self.latest: ImageMsg | None = None
        self.camera_info: CameraInfo | None = None
        self.prior: PoseWithCovarianceStamped | None = None
        self.create_subscription(ImageMsg, p["camera_topic"], self._on_image, 10)
        if p["camera_info_topic"]:
            self.create_subscription(CameraInfo, p["camera_info_topic"], self._on_info, 10)
        if p["prior_topic"]:
            self.create_subscription(
                PoseWithCovarianceStamped, p["prior_topic"], self._on_prior, 10
            )
        self.localizer, self.gallery, self.map_error = self._load_map()
        self.create_timer(1.0 / float(p["localization_frequence"]), self._localize_latest)

    # -- input ---------------------------------------------------------------------------------
    def _load_map(self) -> tuple[MapLocalizer | None, Gallery | None, str]:
        p = self.params
        try:
            if not p["map_dir"]:
                raise VlocbenchError("the map_dir parameter is not set")
            if not (Path(p["map_dir"]) / MAP_FILE).is_file():
                raise VlocbenchError(f"{p['map_dir']} is not a map (no {MAP_FILE})")
            config = LocalizerConfig(
                top_k=int(p["top_k_matches"]), ransac_max_error_px=float(p["ransac_thresh"])
            )
            localizer = MapLocalizer(p["map_dir"], config)
            if p["method"] and method_conf(p["method"]) != localizer.method:
                raise VlocbenchError(
                    f"the map was built with {localizer.method}, not {p['method']!r}"
                )
            return localizer, Gallery.load(localizer.gallery_dir), ""
        except (VlocbenchError, OSError, KeyError, ValueError) as exc:
            message = f"map {p['map_dir']!r} does not load: {exc}"
            self.get_logger().error(message)
            return None, None, message

    def _on_image(self, msg: ImageMsg) -> None:
        with self.lock:
            self.latest = msg

    def _on_info(self, msg: CameraInfo) -> None:
        with self.lock:
            self.camera_info = msg

    def _on_prior(self, msg: PoseWithCovarianceStamped) -> None:
        with self.lock:
            self.prior = msg

    # -- the work ------------------------------------------------------------------------------
    def _localize_latest(self) -> None:
        with self.lock:
            msg, info, prior = self.latest, self.camera_info, self.prior
            self.latest = None  # each image once
        if self.localizer is None:
            self._status(DiagnosticStatus.ERROR, "no map", self.map_error)
            return
        if msg is None:
            return
        start = time.perf_counter()
        stamp = stamp_key(msg.header.stamp)
        try:
            result = self._localize(msg, info, prior)
        except VlocbenchError as exc:
            self.get_logger().error(f"bad input: {exc}")
            self._status(DiagnosticStatus.ERROR, "bad input", str(exc), stamp=stamp)
            return
        seconds = time.perf_counter() - start
        if result.success and result.world_from_cam is not None:
            world_from_base = result.world_from_cam
            sensor_from_base = (
                invert_pose(self.base_from_sensor)
                if self.params["compensate_sensor_offset"]
                else np.eye(4)
            )
            world_from_base = world_from_base @ sensor_from_base
            covariance = (
                result.covariance_of(sensor_from_base, float(self.params["pixel_noise_px"]))
                if self.params["covariance"] == "estimate"
                else None
            )
            if covariance is None:
                covariance = np.eye(6) * float(self.params["pose_variance"])
            self.pose_pub.publish(
                pose_with_covariance(world_from_base, covariance, msg.header.stamp)
            )
        self._status(
            DiagnosticStatus.OK if result.success else DiagnosticStatus.WARN,
            "localized" if result.success else "not localized",
            result.reason,
            inliers=result.num_inliers,
            computation_time_s=seconds,
            stamp=stamp,
            **{f"{stage}_s": round(s, 6) for stage, s in result.seconds.items()},
        )
        if self.marker_pub is not None:
            self.marker_pub.publish(self._markers(result, msg))

    def _localize(
        self, msg: ImageMsg, info: CameraInfo | None, prior: PoseWithCovarianceStamped | None
    ) -> QueryResult:
        assert self.localizer is not None and self.gallery is not None
        image = image_from_msg(msg)
        camera: CameraModel = (
            camera_from_info(info)
            if info is not None
            else next(iter(self.gallery.cameras.values()))
        )
        if (camera.height, camera.width) != image.shape[:2]:
            raise VlocbenchError(
                f"the image is {image.shape[1]}x{image.shape[0]}, its camera "
                f"{camera.width}x{camera.height}"
            )
        prior_world_from_cam = None
        if prior is not None:
            prior_world_from_cam = pose_from_msg(prior.pose.pose)
            if self.params["compensate_sensor_offset"]:
                prior_world_from_cam = prior_world_from_cam @ self.base_from_sensor
        if self.localizer.needs_prior and prior_world_from_cam is None:
            raise VlocbenchError(f"the map needs a prior pose on {self.params['prior_topic']!r}")
        return self.localizer.localize(image, camera, prior_world_from_cam)

    # -- output --------------------------------------------------------------------------------
    def _status(self, level: bytes, state: str, reason: str, **values: Any) -> None:
        status = DiagnosticStatus(
            level=level,
            name=f"vlocbench: {self.get_fully_qualified_name()}",
            message=f"{state}: {reason}" if reason else state,
            hardware_id=str(self.params["map_dir"]),
            values=[KeyValue(key="state", value=state), KeyValue(key="reason", value=reason)]
            + [KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.status_pub.publish(array)

    def _markers(self, result: QueryResult, msg: ImageMsg) -> MarkerArray:
        assert self.gallery is not None
        markers = MarkerArray()
        for k, name in enumerate(result.retrieved):
            pose = self.gallery.images[self.gallery.index_of(name)].world_from_cam
            m = Marker(ns="retrieved", id=k, type=Marker.ARROW, action=Marker.ADD)
            m.header.frame_id, m.header.stamp = "map", msg.header.stamp
            m.pose = pose_to_msg(pose)
            m.scale.x, m.scale.y, m.scale.z = 2.0, 0.3, 0.3
            chosen = name in result.cluster
            m.color.r, m.color.g, m.color.b, m.color.a = (
                (0.1, 0.8, 0.1, 1.0) if chosen else (0.8, 0.5, 0.1, 0.7)
            )
            markers.markers.append(m)
        return markers
