"""Conversions between ROS 2 messages and vlocbench's arrays, without cv_bridge or tf2 (neither
installs from PyPI). Poses are (4, 4) ``a_from_b`` matrices; images (H, W, 3) RGB uint8."""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseWithCovarianceStamped, Quaternion
from sensor_msgs.msg import CameraInfo
from sensor_msgs.msg import Image as ImageMsg
from std_msgs.msg import Header

from vlocbench.errors import LocalizationError
from vlocbench.geometry import make_pose, quaternion_from_rotation, rotation_from_quaternion
from vlocbench.interfaces import Array, Image
from vlocbench.loc.gallery import CameraModel

ENCODINGS = ("rgb8", "bgr8", "mono8")


def sec_nanosec(t_s: float) -> tuple[int, int]:
    """A time in seconds as ROS's (sec, nanosec)."""
    ns = round(t_s * 1e9)
    return ns // 10**9, ns % 10**9


def stamp_of(t_s: float) -> Time:
    sec, nanosec = sec_nanosec(t_s)
    return Time(sec=sec, nanosec=nanosec)


def stamp_key(stamp: Time) -> str:
    """A stamp as text: how the localization node names the image a status is about."""
    return f"{stamp.sec}.{stamp.nanosec:09d}"


def image_from_msg(msg: ImageMsg) -> Image:
    """(H, W, 3) RGB of an ``rgb8``, ``bgr8`` or ``mono8`` image message."""
    if msg.encoding not in ENCODINGS:
        raise LocalizationError(
            f"image encoding {msg.encoding!r} is not supported; use one of {', '.join(ENCODINGS)}"
        )
    channels = 1 if msg.encoding == "mono8" else 3
    if msg.width == 0 or msg.height == 0:
        raise LocalizationError("the image is empty")
    if msg.step < msg.width * channels or len(msg.data) < msg.step * msg.height:
        raise LocalizationError(
            f"the image data ({len(msg.data)} bytes, step {msg.step}) does not hold "
            f"{msg.width}x{msg.height} {msg.encoding} pixels"
        )
    rows = np.frombuffer(bytes(msg.data), np.uint8)[: msg.step * msg.height]
    pixels = rows.reshape(msg.height, msg.step)[:, : msg.width * channels]
    pixels = pixels.reshape(msg.height, msg.width, channels)
    if msg.encoding == "mono8":
        return np.repeat(pixels, 3, axis=2)
    return np.ascontiguousarray(pixels[:, :, ::-1] if msg.encoding == "bgr8" else pixels)


def msg_from_image(rgb: Image, stamp: Time, frame_id: str) -> ImageMsg:
    """An ``rgb8`` message of (H, W, 3) RGB pixels."""
    h, w = rgb.shape[:2]
    return ImageMsg(
        header=Header(stamp=stamp, frame_id=frame_id),
        height=h,
        width=w,
        encoding="rgb8",
        is_bigendian=0,
        step=3 * w,
        data=np.ascontiguousarray(rgb, np.uint8).tobytes(),
    )


def camera_from_info(info: CameraInfo) -> CameraModel:
    """The pinhole camera of a ``CameraInfo`` (its ``k``; distortion must be zero)."""
    K = np.asarray(info.k, np.float64).reshape(3, 3)
    if info.width == 0 or info.height == 0 or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise LocalizationError("camera info: needs a size and positive focal lengths in k")
    if len(info.d) and np.any(np.abs(np.asarray(info.d)) > 1e-9):
        raise LocalizationError("camera info: distorted images are not supported; rectify them")
    return CameraModel(int(info.width), int(info.height), K)


def info_from_camera(camera: CameraModel, stamp: Time, frame_id: str) -> CameraInfo:
    K = np.asarray(camera.K, np.float64)
    P = np.hstack([K, np.zeros((3, 1))])
    return CameraInfo(
        header=Header(stamp=stamp, frame_id=frame_id),
        width=camera.width,
        height=camera.height,
        distortion_model="plumb_bob",
        d=[0.0] * 5,
        k=K.ravel().tolist(),
        r=np.eye(3).ravel().tolist(),
        p=P.ravel().tolist(),
    )


def pose_to_msg(world_from_base: Array) -> Pose:
    x, y, z, w = quaternion_from_rotation(world_from_base[:3, :3])
    t = world_from_base[:3, 3]
    return Pose(
        position=Point(x=float(t[0]), y=float(t[1]), z=float(t[2])),
        orientation=Quaternion(x=x, y=y, z=z, w=w),
    )


def pose_from_msg(pose: Pose) -> Array:
    o, p = pose.orientation, pose.position
    return make_pose(rotation_from_quaternion(o.x, o.y, o.z, o.w), np.array([p.x, p.y, p.z]))


def pose_with_covariance(
    world_from_base: Array, covariance: Array, stamp: Time, frame_id: str = "map"
) -> PoseWithCovarianceStamped:
    """``covariance`` (6, 6) over x, y, z, roll, pitch, yaw, as robot_localization reads it."""
    msg = PoseWithCovarianceStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.pose.pose = pose_to_msg(world_from_base)
    msg.pose.covariance = np.asarray(covariance, np.float64).ravel().tolist()
    return msg
