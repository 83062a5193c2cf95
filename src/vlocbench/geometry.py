"""Rigid-body helpers shared by every stage (pure numpy).

Conventions: world frame right-handed, z up, metres. Poses are 4x4 homogeneous matrices named
``a_from_b`` (maps points in frame b to frame a). Camera frames follow OpenCV (x right, y down,
z forward). Vehicle frame: x forward, y left, z up, origin at the car's centre on the ground.
"""

from __future__ import annotations

import numpy as np

from vlocbench.interfaces import Array

# optical (x right, y down, z forward) from body-style (x forward, y left, z up)
BODY_FROM_OPTICAL: Array = np.array(
    [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]], dtype=np.float64
)


def rot_x(angle_rad: float) -> Array:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)


def rot_y(angle_rad: float) -> Array:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)


def rot_z(angle_rad: float) -> Array:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float64)


def rpy_to_matrix(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Array:
    """R = Rz(yaw) @ Ry(pitch) @ Rx(roll) (intrinsic z-y-x). With z up, positive pitch tilts x down."""
    return rot_z(yaw_rad) @ rot_y(pitch_rad) @ rot_x(roll_rad)


def make_pose(rotation: Array, translation: Array) -> Array:
    """4x4 pose from a 3x3 rotation and a 3-vector translation."""
    pose = np.eye(4)
    pose[:3, :3] = rotation
    pose[:3, 3] = translation
    return pose


def planar_pose(x_m: float, y_m: float, yaw_rad: float, z_m: float = 0.0) -> Array:
    """world_from_body for a body on the ground plane at (x, y) heading ``yaw_rad``."""
    return make_pose(rot_z(yaw_rad), np.array([x_m, y_m, z_m]))


def invert_pose(a_from_b: Array) -> Array:
    """b_from_a for a rigid a_from_b."""
    rot = a_from_b[:3, :3]
    out = np.eye(4)
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ a_from_b[:3, 3]
    return out


def pose_error(true_world_from_a: Array, est_world_from_a: Array) -> tuple[float, float]:
    """(3D position error m, rotation error deg) between two (4, 4) poses: the distance between
    their origins and the angle of the rotation between them, arccos((trace(R_t^T R_e) - 1) / 2)."""
    position = float(np.linalg.norm(est_world_from_a[:3, 3] - true_world_from_a[:3, 3]))
    cos = (np.trace(true_world_from_a[:3, :3].T @ est_world_from_a[:3, :3]) - 1.0) / 2.0
    return position, float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def quaternion_from_rotation(R: Array) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation matrix (w >= 0)."""
    w = np.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2
    y = np.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2
    z = np.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2
    x = float(np.copysign(x, R[2, 1] - R[1, 2]))
    y = float(np.copysign(y, R[0, 2] - R[2, 0]))
    z = float(np.copysign(z, R[1, 0] - R[0, 1]))
    q = np.array([x, y, z, w])
    return tuple(float(v) for v in q / np.linalg.norm(q))  # type: ignore[return-value]


def rotation_from_quaternion(x: float, y: float, z: float, w: float) -> Array:
    """The rotation matrix of a quaternion (x, y, z, w), normalized first."""
    q = np.array([x, y, z, w], np.float64)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rpy_of(rotation: Array) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in rad of a rotation matrix, the inverse of :func:`rpy_to_matrix`."""
    pitch = float(np.arcsin(np.clip(-rotation[2, 0], -1.0, 1.0)))
    return (
        float(np.arctan2(rotation[2, 1], rotation[2, 2])),
        pitch,
        float(np.arctan2(rotation[1, 0], rotation[0, 0])),
    )


def skew(v: Array) -> Array:
    """(3, 3) cross-product matrix of a 3-vector: ``skew(a) @ b == np.cross(a, b)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


# of a (6, 6) pose covariance over (position x, y, z; rotation x, y, z): the rows and columns of
# the planar pose (x, y, yaw), the rotation about z being the yaw near level
PLANAR_OF_POSE = [0, 1, 5]


def covariance_through_offset(
    world_from_a_covariance: Array, world_from_a: Array, a_from_b: Array
) -> Array:
    """The (6, 6) covariance of ``world_from_b = world_from_a @ a_from_b`` for a fixed ``a_from_b``.

    Both covariances are over (position x, y, z in the world, m; rotation vector of a small
    rotation applied on the world side, rad), the convention of ROS pose covariances near level.
    The rotation error moves b's origin by its lever arm ``world_from_a[:3, :3] @ a_from_b[:3, 3]``.
    """
    lever_m = world_from_a[:3, :3] @ a_from_b[:3, 3]
    jacobian = np.eye(6)
    jacobian[:3, 3:] = -skew(lever_m)
    return jacobian @ world_from_a_covariance @ jacobian.T


def wrap_angle(angle_rad: float | Array) -> float | Array:
    """Wrap to [-pi, pi)."""
    return (np.asarray(angle_rad) + np.pi) % (2 * np.pi) - np.pi


def resample_polyline(points_xy: Array, spacing_m: float) -> Array:
    """Resample an (N, 2) polyline at equal arc length ``spacing_m``, keeping both ends.

    Returns (M, 2) with M = ceil(length / spacing) + 1; the last step may be shorter.
    """
    seg = np.linalg.norm(np.diff(points_xy, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])
    points_xy = points_xy[keep]
    s = np.concatenate([[0.0], np.cumsum(seg[seg > 1e-9])])
    total = float(s[-1])
    n = max(1, int(np.ceil(total / spacing_m - 1e-9)))
    samples = np.append(np.arange(n) * spacing_m, total)
    x = np.interp(samples, s, points_xy[:, 0])
    y = np.interp(samples, s, points_xy[:, 1])
    return np.stack([x, y], axis=1)


def polyline_length(points_xy: Array) -> float:
    return float(np.linalg.norm(np.diff(points_xy, axis=0), axis=1).sum())


def headings_of(points_xy: Array) -> Array:
    """Heading (rad) at each point of an (N, 2) polyline, from the segment that leaves it."""
    d = np.diff(points_xy, axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    return np.append(yaw, yaw[-1])
