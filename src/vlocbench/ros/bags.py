"""Episodes as rosbag2 (MCAP) files, written with the pure-Python ``rosbags`` (no ROS install).

Per episode, in simulated time (the episode starts at 0 s): ``/ground_truth/odom`` and
``/ekf/odom`` (``nav_msgs/Odometry`` at every simulation step: the true pose and speed, the EKF's
pose), ``/wheel_odometry`` (``geometry_msgs/TwistWithCovarianceStamped``: the noisy reading the
EKF got for each step, with the noise model's variances), ``/visual_pose_estimate``
(``geometry_msgs/PoseWithCovarianceStamped``, each answer of the localizer, written when it
reached the EKF and stamped with its image's time, covariance the paper's 0.1) and ``/visual_pose_truth`` (the true pose at those image times). evo (``evo_ape bag2``),
Foxglove and rviz read them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from vlocbench.bench.store import read_episode_table, read_latest_run
from vlocbench.config import from_dict
from vlocbench.geometry import planar_pose, quaternion_from_rotation
from vlocbench.nav import OdometryNoise
from vlocbench.ros.messages import sec_nanosec

POSE_VARIANCE = 0.1  # the paper's localization node's fixed covariance
_TS = get_typestore(Stores.ROS2_KILTED)
_T = _TS.types


def _stamp(t_s: float) -> Any:
    sec, nanosec = sec_nanosec(t_s)
    return _T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _pose(x_m: float, y_m: float, yaw_rad: float) -> Any:
    qx, qy, qz, qw = quaternion_from_rotation(planar_pose(x_m, y_m, yaw_rad)[:3, :3])
    return _T["geometry_msgs/msg/Pose"](
        position=_T["geometry_msgs/msg/Point"](x=x_m, y=y_m, z=0.0),
        orientation=_T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
    )


def _odometry(t_s: float, pose: Any, speed_mps: float, child: str) -> Any:
    zero = _T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return _T["nav_msgs/msg/Odometry"](
        header=_T["std_msgs/msg/Header"](stamp=_stamp(t_s), frame_id="map"),
        child_frame_id=child,
        pose=_T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=_T["geometry_msgs/msg/TwistWithCovariance"](
            twist=_T["geometry_msgs/msg/Twist"](
                linear=_T["geometry_msgs/msg/Vector3"](x=speed_mps, y=0.0, z=0.0), angular=zero
            ),
            covariance=np.zeros(36),
        ),
    )


def _pose_stamped(t_s: float, pose: Any, variance: float) -> Any:
    return _T["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=_T["std_msgs/msg/Header"](stamp=_stamp(t_s), frame_id="map"),
        pose=_T["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose, covariance=(np.eye(6) * variance).ravel()
        ),
    )


def _wheel(t_s: float, speed_mps: float, yaw_rate_radps: float, noise: OdometryNoise) -> Any:
    sigma_v, sigma_w = noise.sigmas(speed_mps)
    covariance = np.zeros(36)
    covariance[0], covariance[35] = sigma_v**2, sigma_w**2
    vector = _T["geometry_msgs/msg/Vector3"]
    return _T["geometry_msgs/msg/TwistWithCovarianceStamped"](
        header=_T["std_msgs/msg/Header"](stamp=_stamp(t_s), frame_id="base_link"),
        twist=_T["geometry_msgs/msg/TwistWithCovariance"](
            twist=_T["geometry_msgs/msg/Twist"](
                linear=vector(x=speed_mps, y=0.0, z=0.0),
                angular=vector(x=0.0, y=0.0, z=yaw_rate_radps),
            ),
            covariance=covariance,
        ),
    )


def write_episode_bag(output_dir: str | Path, key: str, path: Path,
                      noise: OdometryNoise | None = None) -> Path:  # fmt: skip
    """The episode ``key`` stored in ``output_dir`` as a rosbag2 folder (one MCAP file) at
    ``path``; ``noise``: the episode's odometry model (its variances go with the readings)."""
    noise = noise or OdometryNoise()
    tr = read_episode_table(output_dir, key, "trajectory")
    locs = read_episode_table(output_dir, key, "localizations")
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    with writer:
        topics = {
            "/ground_truth/odom": "nav_msgs/msg/Odometry",
            "/ekf/odom": "nav_msgs/msg/Odometry",
            "/wheel_odometry": "geometry_msgs/msg/TwistWithCovarianceStamped",
            "/visual_pose_estimate": "geometry_msgs/msg/PoseWithCovarianceStamped",
            "/visual_pose_truth": "geometry_msgs/msg/PoseWithCovarianceStamped",
        }
        conn = {t: writer.add_connection(t, m, typestore=_TS) for t, m in topics.items()}
        messages: list[tuple[float, str, Any]] = []
        for k, t in enumerate(tr["time_s"]):
            truth = _pose(tr["true_x_m"][k], tr["true_y_m"][k], tr["true_yaw_rad"][k])
            ekf = _pose(tr["ekf_x_m"][k], tr["ekf_y_m"][k], tr["ekf_yaw_rad"][k])
            messages.append(
                (t, "/ground_truth/odom", _odometry(t, truth, tr["speed_mps"][k], "base_link"))
            )
            messages.append((t, "/ekf/odom", _odometry(t, ekf, tr["speed_mps"][k], "base_link")))
            speed = tr.get("odometry_speed_mps")  # episodes stored before it have none
            if speed is not None and np.isfinite(speed[k]):
                reading = _wheel(t, speed[k], tr["odometry_yaw_rate_radps"][k], noise)
                messages.append((t, "/wheel_odometry", reading))
        for k, t in enumerate(locs.get("time_s", [])):
            if not locs["success"][k]:
                continue
            estimate = _pose(locs["x_m"][k], locs["y_m"][k], locs["yaw_rad"][k])
            truth = _pose(locs["true_x_m"][k], locs["true_y_m"][k], locs["true_yaw_rad"][k])
            arrival = t + locs["latency_s"][k]
            messages.append(
                (arrival, "/visual_pose_estimate", _pose_stamped(t, estimate, POSE_VARIANCE))
            )
            messages.append((arrival, "/visual_pose_truth", _pose_stamped(t, truth, 0.0)))
        for t, topic, msg in sorted(messages, key=lambda m: m[0]):
            writer.write(conn[topic], round(t * 1e9), _TS.serialize_cdr(msg, topics[topic]))
    return path


def export_bags(output_dir: str | Path) -> list[Path]:
    """Every finished episode of the latest run in ``output_dir`` as ``OUTPUT/bags/KEY`` (bags
    already there are kept); returns the bags written."""
    _, rows = read_latest_run(output_dir)
    out = Path(output_dir) / "bags"
    out.mkdir(parents=True, exist_ok=True)
    return [
        write_episode_bag(output_dir, row.key, out / row.key,
                          from_dict(OdometryNoise, row.config.get("episode", {}).get("odometry", {})))
        for row in rows
        if row.status == "ok" and not (out / row.key).exists()
    ]  # fmt: skip
