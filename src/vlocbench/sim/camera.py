"""Cameras mounted on the vehicle: intrinsics (pinhole, square pixels) and extrinsics.

Extrinsics are given in the vehicle frame (x forward, y left, z up, origin at the car's centre on the
ground): position in metres and roll/pitch/yaw in degrees, R = Rz(yaw) Ry(pitch) Rx(roll). A positive
pitch tilts the camera down (right-hand rule about the left-pointing y axis); yaw -90 looks to the
right. Images and poses use OpenCV's optical frame (x right, y down, z forward) and pixel centres at
integer coordinates.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from vlocbench.config import default_changed, require
from vlocbench.geometry import BODY_FROM_OPTICAL, make_pose, rpy_to_matrix
from vlocbench.interfaces import Array


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole camera: ``fov_deg`` is the horizontal field of view."""

    width: int = 800
    height: int = 600
    fov_deg: float = 90.0

    def __post_init__(self) -> None:
        require(0.0 < self.fov_deg < 180.0, "fov_deg", f"must be in (0, 180), got {self.fov_deg:g}")
        require(16 <= self.width <= 2048, "width", f"must be in [16, 2048] px, got {self.width}")
        require(16 <= self.height <= 2048, "height", f"must be in [16, 2048] px, got {self.height}")

    @property
    def focal_px(self) -> float:
        return 0.5 * self.width / float(np.tan(np.radians(self.fov_deg) / 2))

    @property
    def K(self) -> Array:
        """3x3 calibration matrix, OpenCV convention (pixel centres at integers)."""
        f = self.focal_px
        return np.array([[f, 0, self.width / 2 - 0.5], [0, f, self.height / 2 - 0.5], [0, 0, 1.0]])


@dataclass(frozen=True)
class Extrinsics:
    """Mounting pose in the vehicle frame (metres, degrees). Default: the paper's gallery camera."""

    x_m: float = 2.0
    y_m: float = 0.0
    z_m: float = 2.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = -90.0

    def __post_init__(self) -> None:
        require(self.z_m > 0.0, "z_m", f"the camera must be above the ground, got {self.z_m:g}")
        require(-90.0 <= self.pitch_deg <= 90.0, "pitch_deg", "must be in [-90, 90]")

    def vehicle_from_cam(self) -> Array:
        """4x4 pose of the optical camera frame in the vehicle frame."""
        rot = rpy_to_matrix(*np.radians([self.roll_deg, self.pitch_deg, self.yaw_deg]))
        return make_pose(rot @ BODY_FROM_OPTICAL, np.array([self.x_m, self.y_m, self.z_m]))


@dataclass(frozen=True)
class Camera:
    """A camera of the rig. ``antialias``: ``False`` (the default) samples each pixel once, with
    stair-stepped edges, as CARLA's camera images are (its sensors skip the engine's
    anti-aliasing); ``True`` averages 4 samples per pixel (4x multisampling), as a real sensor
    integrates light over its pixel, at about twice the render time on Mesa's llvmpipe."""

    name: str = "gallery"
    intrinsics: Intrinsics = field(default_factory=Intrinsics)
    extrinsics: Extrinsics = field(default_factory=Extrinsics)
    antialias: bool = field(default=False, metadata=default_changed(True))

    def world_from_cam(self, world_from_vehicle: Array) -> Array:
        return world_from_vehicle @ self.extrinsics.vehicle_from_cam()

    def offset(self, dz_m: float = 0.0, pitch_down_deg: float = 0.0) -> Camera:
        """This camera raised by ``dz_m`` and tilted down by ``pitch_down_deg`` (viewpoint change)."""
        e = self.extrinsics
        ext = dataclasses.replace(e, z_m=e.z_m + dz_m, pitch_deg=e.pitch_deg + pitch_down_deg)
        return dataclasses.replace(self, extrinsics=ext)


def gallery_camera() -> Camera:
    """The paper's gallery camera: 800x600, FOV 90, facing right, 2 m forward, 2 m up."""
    return Camera()


def project(K: Array, cam_from_world: Array, points_world: Array) -> tuple[Array, Array]:
    """Project (N, 3) world points: pixel coordinates (N, 2) and depth (N,) in the camera."""
    pc = points_world @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    uv = pc @ K.T
    return uv[:, :2] / uv[:, 2:3], pc[:, 2]
