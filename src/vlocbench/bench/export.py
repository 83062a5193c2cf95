"""A run's episodes in the field's formats, so that evo and hloc's scripts score them.

Per finished episode of the latest run, in ``OUTPUT/export/FORMAT/KEY/``:

- ``tum``: ``timestamp tx ty tz qx qy qz qw`` of world_from_vehicle (the simulation's time, s):
  ``truth.txt`` and ``ekf.txt`` at every simulation step, ``estimates.txt`` (the localizer's
  answers, at their image times) and ``estimates_truth.txt`` (the truth at those times), so that
  ``evo_ape tum truth.txt ekf.txt`` and ``evo_ape tum estimates_truth.txt estimates.txt`` need no
  alignment;
- ``kitti``: the same four files as 3x4 row-major world_from_vehicle matrices, a line a pose (KITTI
  has no time: the files of a pair line up row by row);
- ``hloc`` (recall drives): ``results.txt``, hloc's localization results ``name qw qx qy qz tx ty
  tz`` of cam_from_world (COLMAP's convention) for each answered query image and camera,
  ``ground_truth.txt`` the true poses alike for every query, and ``queries_with_intrinsics.txt``
  (``name PINHOLE width height fx fy cx cy``, COLMAP's pixel centres); no header line, as hloc
  writes them and as its readers expect;
- ``colmap``: per gallery the run's maps were built from, in ``OUTPUT/export/colmap/GALLERY/``, a
  COLMAP text model with its cameras and images at their known poses and no points (what hloc's
  triangulation starts from; the images stay in the gallery's ``images/``).

Query images are named ``CAMERA/NNNNNN.png`` by the localization's index in the episode. The
formatting functions are pure; only :func:`export_run` reads and writes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vlocbench.bench.runs import Experiment, stored_rows
from vlocbench.bench.store import EpisodeRow, read_episode_table
from vlocbench.bench.visual import camera_model
from vlocbench.config import from_dict, require_one_of
from vlocbench.geometry import invert_pose, make_pose, quaternion_from_rotation, rpy_to_matrix
from vlocbench.interfaces import Array
from vlocbench.loc.gallery import Gallery
from vlocbench.loc.mapping import export_colmap, map_info
from vlocbench.sim.camera import Camera

FORMATS = ("tum", "kitti", "hloc", "colmap")
EXPORT_DIR = "export"


def vehicle_poses(
    x_m: Array,
    y_m: Array,
    yaw_rad: Array,
    z_m: Array | None = None,
    roll_rad: Array | None = None,
    pitch_rad: Array | None = None,
) -> Array:
    """(N, 4, 4) world_from_vehicle of N poses given by columns (N,); z, roll, pitch 0 if None."""
    n = len(x_m)
    z, roll, pitch = (np.zeros(n) if c is None else c for c in (z_m, roll_rad, pitch_rad))
    return np.array(
        [
            make_pose(
                rpy_to_matrix(roll[k], pitch[k], yaw_rad[k]), np.array([x_m[k], y_m[k], z[k]])
            )
            for k in range(n)
        ]
    ).reshape(n, 4, 4)


def tum_lines(times_s: Array, poses: Array) -> list[str]:
    """TUM lines ``timestamp tx ty tz qx qy qz qw`` of (N,) times and (N, 4, 4) poses."""
    return [
        " ".join(f"{v:.9g}" for v in (t, *pose[:3, 3], *quaternion_from_rotation(pose[:3, :3])))
        for t, pose in zip(times_s, poses, strict=True)
    ]


def kitti_lines(poses: Array) -> list[str]:
    """KITTI lines: the top 3x4 of each (4, 4) pose, row-major."""
    return [" ".join(f"{v:.9g}" for v in pose[:3, :4].ravel()) for pose in poses]


def hloc_lines(names: Sequence[str], cam_from_world: Array) -> list[str]:
    """hloc's results lines ``name qw qx qy qz tx ty tz`` of (N, 4, 4) cam_from_world poses."""
    lines = []
    for name, pose in zip(names, cam_from_world, strict=True):
        qx, qy, qz, qw = quaternion_from_rotation(pose[:3, :3])
        lines.append(" ".join([name, *(f"{v:.9g}" for v in (qw, qx, qy, qz, *pose[:3, 3]))]))
    return lines


def colmap_intrinsics_line(name: str, camera: Camera) -> str:
    """``name PINHOLE width height fx fy cx cy`` with COLMAP's principal point (pixel centres at
    +0.5, where ours, OpenCV's, are at integers)."""
    model = camera_model(camera)
    K = model.K
    params = (K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5)
    return f"{name} PINHOLE {model.width} {model.height} " + " ".join(f"{v:.9g}" for v in params)


def localizations(output_dir: str | Path, key: str) -> dict[str, Array]:
    """The episode's stored localizations as columns; empty when it localized nothing (an
    odometry-only episode stores a table without columns)."""
    locs = read_episode_table(output_dir, key, "localizations")
    return locs if "success" in locs else {}


def estimate_poses(locs: dict[str, Array], rows: NDArray[np.integer]) -> Array:
    """(R, 4, 4) world_from_vehicle of the stored estimates at ``rows``; episodes stored before
    the 6-DoF columns were kept have only x, y, yaw."""
    six_dof = all(c in locs for c in ("z_m", "roll_rad", "pitch_rad"))
    return vehicle_poses(
        locs["x_m"][rows],
        locs["y_m"][rows],
        locs["yaw_rad"][rows],
        *((locs[c][rows] for c in ("z_m", "roll_rad", "pitch_rad")) if six_dof else ()),
    )


def _write(path: Path, lines: list[str]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(f"{x}\n" for x in lines))
    return path


def export_episode(
    output_dir: str | Path, key: str, config: dict[str, Any], fmt: str, dest: Path
) -> list[Path]:
    """The episode ``key`` (its stored ``config``) in ``fmt`` into the folder ``dest``."""
    require_one_of(fmt, FORMATS, "format")
    tr = read_episode_table(output_dir, key, "trajectory")
    locs = localizations(output_dir, key)
    if fmt == "hloc":
        recall = config.get("kind") == "recall" and locs
        return _export_hloc(locs, config, dest) if recall else []
    series = {
        "truth": (tr["time_s"], vehicle_poses(tr["true_x_m"], tr["true_y_m"], tr["true_yaw_rad"])),
        "ekf": (tr["time_s"], vehicle_poses(tr["ekf_x_m"], tr["ekf_y_m"], tr["ekf_yaw_rad"])),
    }
    if locs:
        answered = np.flatnonzero(locs["success"])
        true = [locs[c][answered] for c in ("true_x_m", "true_y_m", "true_yaw_rad")]
        series["estimates"] = (locs["time_s"][answered], estimate_poses(locs, answered))
        series["estimates_truth"] = (locs["time_s"][answered], vehicle_poses(*true))
    if fmt == "tum":
        return [_write(dest / f"{n}.txt", tum_lines(t, p)) for n, (t, p) in series.items()]
    return [_write(dest / f"{n}.txt", kitti_lines(p)) for n, (_, p) in series.items()]


def _export_hloc(locs: dict[str, Array], config: dict[str, Any], dest: Path) -> list[Path]:
    cameras = [from_dict(Camera, c) for c in config["setup"]["cameras"]]
    everything = np.arange(len(locs["time_s"]))
    answered = np.flatnonzero(locs["success"])
    true = vehicle_poses(*(locs[c] for c in ("true_x_m", "true_y_m", "true_yaw_rad")))

    def named(rows: NDArray[np.integer], world_from_vehicle: Array) -> tuple[list[str], Array]:
        names, poses = [], []
        for cam in cameras:
            vehicle_from_cam = cam.extrinsics.vehicle_from_cam()
            for k, pose in zip(rows, world_from_vehicle, strict=True):
                names.append(f"{cam.name}/{k:06d}.png")
                poses.append(invert_pose(pose @ vehicle_from_cam))
        return names, np.array(poses).reshape(-1, 4, 4)

    # no header line: hloc's readers take every line as a name and its numbers
    estimates = hloc_lines(*named(answered, estimate_poses(locs, answered)))
    intrinsics = [
        colmap_intrinsics_line(f"{c.name}/{k:06d}.png", c) for c in cameras for k in everything
    ]
    return [
        _write(dest / "results.txt", estimates),
        _write(dest / "ground_truth.txt", hloc_lines(*named(everything, true))),
        _write(dest / "queries_with_intrinsics.txt", intrinsics),
    ]


def export_run(
    output_dir: str | Path, fmt: str, experiment: Experiment | None = None
) -> list[Path]:
    """Every finished episode of the latest run in ``output_dir`` (or of ``experiment``) as
    ``fmt`` in ``OUTPUT/export/FMT/KEY/`` (written again each time); returns the files written."""
    require_one_of(fmt, FORMATS, "format")
    rows = stored_rows(output_dir, experiment)
    out = Path(output_dir) / EXPORT_DIR / fmt
    if fmt == "colmap":
        return [export_colmap(g, out / g.root.name) for g in _galleries(rows)]
    written: list[Path] = []
    for row in rows:
        if row.status == "ok":
            written += export_episode(output_dir, row.key, row.config, fmt, out / row.key)
    return written


def _galleries(rows: Sequence[EpisodeRow]) -> list[Gallery]:
    """The galleries of the maps the episodes used, once each."""
    folders = {row.config["map_dir"] for row in rows if row.config.get("map_dir")}
    galleries = {str(map_info(f)[1]) for f in folders}
    return [Gallery.load(g) for g in sorted(galleries)]
