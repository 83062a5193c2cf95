"""Episodes as rosbag2 (MCAP) files, written with the pure-Python ``rosbags`` (no ROS install).

Per episode, in simulated time (the episode starts at 0 s): ``/ground_truth/odom`` and
``/ekf/odom`` (``nav_msgs/Odometry`` at every simulation step: the true pose and speed, the EKF's
pose), ``/wheel_odometry`` (``geometry_msgs/TwistWithCovarianceStamped``: the noisy reading the
EKF got for each step, with the noise model's variances), ``/visual_pose_estimate``
(``geometry_msgs/PoseWithCovarianceStamped``: each answer of the localizer in 6-DoF, written
when it reached the EKF and stamped with its image's time, with the covariance the EKF got: the
answer's own where the localizer gave one, else x, y and yaw from the episode's ``ekf`` config,
the paper's 0.1) and ``/visual_pose_truth`` (the
true pose at those image times). With ``images``, every query (answered or not) as
``/CAMERA/image/compressed`` (``sensor_msgs/CompressedImage``, JPEG, stamped and written at its
image's time) and ``/CAMERA/camera_info``, rendered again from the true pose
(:mod:`vlocbench.bench.replay`: traffic is not replayed). evo (``evo_ape bag2``), Foxglove and rviz
read them.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from vlocbench.bench.export import estimate_poses, localizations, vehicle_poses
from vlocbench.bench.replay import QueryRenderer
from vlocbench.bench.runs import Experiment, stored_rows
from vlocbench.bench.store import EpisodeRow, read_episode_table
from vlocbench.bench.visual import camera_model
from vlocbench.config import from_dict
from vlocbench.geometry import PLANAR_OF_POSE, quaternion_from_rotation
from vlocbench.interfaces import Array
from vlocbench.nav import EkfConfig, OdometryNoise
from vlocbench.ros.messages import sec_nanosec

JPEG_QUALITY = 90
_TS = get_typestore(Stores.ROS2_KILTED)
_T = _TS.types


def _stamp(t_s: float) -> Any:
    sec, nanosec = sec_nanosec(t_s)
    return _T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def _pose(world_from_base: Array) -> Any:
    qx, qy, qz, qw = quaternion_from_rotation(world_from_base[:3, :3])
    x, y, z = (float(v) for v in world_from_base[:3, 3])
    return _T["geometry_msgs/msg/Pose"](
        position=_T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
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


def _pose_stamped(t_s: float, pose: Any, covariance: Array) -> Any:
    """``covariance`` (6, 6) over x, y, z, roll, pitch, yaw."""
    return _T["geometry_msgs/msg/PoseWithCovarianceStamped"](
        header=_T["std_msgs/msg/Header"](stamp=_stamp(t_s), frame_id="map"),
        pose=_T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=covariance.ravel()),
    )


def _pose_covariance(planar: Array) -> Array:
    """(6, 6) over x, y, z, roll, pitch, yaw from the (3, 3) over x, y, yaw; z, roll, pitch 0."""
    covariance = np.zeros((6, 6))
    covariance[np.ix_(PLANAR_OF_POSE, PLANAR_OF_POSE)] = planar
    return covariance


def _answer_covariance(locs: dict[str, Array], k: int, default: Array) -> Array:
    """(6, 6): the covariance the EKF got with answer ``k``, the answer's own where the localizer
    gave one (episodes stored before it was kept have none), else ``default``."""
    own = locs["covariance"][k] if "covariance" in locs else ()
    return _pose_covariance(np.reshape(own, (3, 3))) if len(own) == 9 else default


def _image_messages(config: dict[str, Any], locs: dict[str, Array]) -> list[tuple[float, str, Any]]:
    """Each query's image (JPEG) and camera info at its image time, rendered again."""
    import cv2

    messages: list[tuple[float, str, Any]] = []
    with QueryRenderer(config) as renderer:
        name = renderer.camera.name
        model = camera_model(renderer.camera)
        K = np.asarray(model.K, np.float64)
        for k, t in enumerate(locs["time_s"]):
            truth = (locs["true_x_m"][k], locs["true_y_m"][k], locs["true_yaw_rad"][k])
            bgr = cv2.cvtColor(renderer.image(*truth, float(t)), cv2.COLOR_RGB2BGR)
            ok, jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
            assert ok, "OpenCV could not encode a JPEG"
            header = _T["std_msgs/msg/Header"](stamp=_stamp(t), frame_id=name)
            image = _T["sensor_msgs/msg/CompressedImage"](
                header=header, format="rgb8; jpeg compressed bgr8", data=jpeg.ravel()
            )
            info = _T["sensor_msgs/msg/CameraInfo"](
                header=header,
                height=model.height,
                width=model.width,
                distortion_model="plumb_bob",
                d=np.zeros(5),
                k=K.ravel(),
                r=np.eye(3).ravel(),
                p=np.hstack([K, np.zeros((3, 1))]).ravel(),
                binning_x=0,
                binning_y=0,
                roi=_T["sensor_msgs/msg/RegionOfInterest"](
                    x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
                ),
            )
            messages += [(t, f"/{name}/image/compressed", image), (t, f"/{name}/camera_info", info)]
    return messages


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


def write_episode_bag(
    output_dir: str | Path, row: EpisodeRow, path: Path, images: bool = False
) -> Path:
    """The finished episode ``row`` stored in ``output_dir`` as a rosbag2 folder (one MCAP file)
    at ``path``, written whole or not at all; ``images``: with the query images."""
    episode = row.config.get("episode", {})
    noise = from_dict(OdometryNoise, episode.get("odometry", {}))
    default = _pose_covariance(from_dict(EkfConfig, episode.get("ekf", {})).pose_covariance())
    tr = read_episode_table(output_dir, row.key, "trajectory")
    locs = localizations(output_dir, row.key)
    messages: list[tuple[float, str, Any]] = []
    true = vehicle_poses(tr["true_x_m"], tr["true_y_m"], tr["true_yaw_rad"])
    ekf = vehicle_poses(tr["ekf_x_m"], tr["ekf_y_m"], tr["ekf_yaw_rad"])
    speed = tr.get("odometry_speed_mps")  # episodes stored before it have none
    for k, t in enumerate(tr["time_s"]):
        speed_mps = tr["speed_mps"][k]
        messages.append(
            (t, "/ground_truth/odom", _odometry(t, _pose(true[k]), speed_mps, "base_link"))
        )
        messages.append((t, "/ekf/odom", _odometry(t, _pose(ekf[k]), speed_mps, "base_link")))
        if speed is not None and np.isfinite(speed[k]):
            reading = _wheel(t, speed[k], tr["odometry_yaw_rate_radps"][k], noise)
            messages.append((t, "/wheel_odometry", reading))
    if locs:
        answered = np.flatnonzero(locs["success"])
        truths = vehicle_poses(
            *(locs[c][answered] for c in ("true_x_m", "true_y_m", "true_yaw_rad"))
        )
        for answer, estimate, truth in zip(
            answered, estimate_poses(locs, answered), truths, strict=True
        ):
            t = locs["time_s"][answer]
            arrival = t + locs["latency_s"][answer]
            covariance = _answer_covariance(locs, int(answer), default)
            messages.append(
                (arrival, "/visual_pose_estimate", _pose_stamped(t, _pose(estimate), covariance))
            )
            messages.append(
                (arrival, "/visual_pose_truth", _pose_stamped(t, _pose(truth), np.zeros((6, 6))))
            )
        if images:
            messages += _image_messages(row.config, locs)
    partial = path.with_name(path.name + ".partial")
    shutil.rmtree(partial, ignore_errors=True)
    with Writer(partial, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = {
            topic: writer.add_connection(topic, msg.__msgtype__, typestore=_TS)
            for topic, msg in {m[1]: m[2] for m in messages}.items()
        }
        for t, topic, msg in sorted(messages, key=lambda m: m[0]):
            writer.write(conn[topic], round(t * 1e9), _TS.serialize_cdr(msg, msg.__msgtype__))
    shutil.rmtree(path, ignore_errors=True)
    partial.rename(path)
    return path


def _has_images(bag: Path) -> bool:
    with Reader(bag) as reader:
        return any(c.topic.endswith("/image/compressed") for c in reader.connections)


def export_bags(
    output_dir: str | Path, images: bool = False, experiment: Experiment | None = None
) -> list[Path]:
    """Every finished episode of the latest run in ``output_dir`` (or of ``experiment``) as
    ``OUTPUT/bags/KEY`` (bags already there are kept, unless ``images`` asks for what they lack);
    returns the bags written."""
    rows = stored_rows(output_dir, experiment)
    out = Path(output_dir) / "bags"
    out.mkdir(parents=True, exist_ok=True)
    todo = [
        row
        for row in rows
        if row.status == "ok"
        and not ((out / row.key).exists() and (not images or _has_images(out / row.key)))
    ]
    return [write_episode_bag(output_dir, row, out / row.key, images) for row in todo]
