"""An episode in 3D: a rerun recording (``vlocbench view``; needs the ``view`` extra).

What it holds, on the ``sim_time`` timeline (seconds of the episode) where things move:

- ``town/buildings`` (boxes) and ``route`` (the line the car should follow), static;
- ``truth`` and ``ekf``: the car's true and filtered poses (a box each) over time, and
  ``truth/path`` / ``ekf/path`` the whole trajectories;
- ``localization``: each answer of the localizer at its image time, the camera as a frustum
  coloured by its error (green within (0.25 m, 2°), yellow within (5 m, 10°), red beyond; grey when
  the EKF rejected it), and ``localization/log`` a line for every query, failures with their reason;
- ``failures``: where the car failed (red), with the cause;
- ``errors/*``: the answer's position and rotation errors as plots;
- with ``images``: the query image rendered again from the true pose (traffic is not replayed)
  under ``localization/camera/image``, and the first retrieved gallery images under ``retrieved/k``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from vlocbench.bench.experiment import setup_names, short_label
from vlocbench.bench.export import estimate_poses, localizations
from vlocbench.bench.replay import QueryRenderer, episode_camera
from vlocbench.bench.runs import Experiment, stored_episodes
from vlocbench.bench.store import EpisodeRow, StoreError, read_episode_table, read_episodes
from vlocbench.bench.towns import route_named, town_named
from vlocbench.bench.visual import camera_model
from vlocbench.errors import MachineError
from vlocbench.geometry import planar_pose
from vlocbench.interfaces import Array, Image
from vlocbench.sim.town import Town

VIEW_DIR = "view"  # recordings go to OUTPUT/view/KEY.rrd by default
RETRIEVED_SHOWN = 3  # gallery images shown beside a query
CAR_HALF_SIZE_M = (2.25, 0.9, 0.75)
GOOD, FAIR, WRONG, REJECTED = (40, 200, 60), (230, 200, 40), (220, 40, 40), (140, 140, 140)


def _rerun() -> Any:
    try:
        import rerun
    except ImportError as exc:
        raise MachineError(
            f"the view extra is not installed ({exc}): pip install 'vlocbench[view]'"
        ) from None
    return rerun


def choose_episode(
    output_dir: str | Path,
    key: str | None = None,
    setup: str | None = None,
    method: str | None = None,
    experiment: Experiment | None = None,
    *,
    town: str | None = None,
    kind: str | None = None,
    repetition: int | None = None,
    failed: bool = False,
) -> EpisodeRow:
    """The finished episode ``key`` (any stored one), or the first one (failure drives first,
    then by repetition) of the latest run or of ``experiment`` that fits every filter given:
    ``setup``, ``method``, ``town`` (its name or its spec), ``kind``, ``repetition``, and
    ``failed`` (a drive with at least one failure); a clear error lists what there is."""
    if key is not None:
        done = [r for r in read_episodes(output_dir) if r.status == "ok"]
        match = [r for r in done if r.key == key or r.key.startswith(key)]
        if len(match) != 1:
            raise StoreError(f"{output_dir}: {len(match)} finished episodes match key {key!r}")
        return match[0]
    plan, rows = stored_episodes(output_dir, experiment)
    done = [r for r in rows if r.status == "ok"]
    named = {x.label: setup_names(x) for x in plan.setups}
    labels = plan.setups_by_key  # the plan's names of each episode, whichever plan stored it

    def names(r: EpisodeRow) -> set[str]:
        here = labels.get(r.key, (r.setup,))
        return {n for x in here for n in named.get(x, (x, short_label(x)))}

    def fits(r: EpisodeRow) -> bool:
        return (
            (setup is None or setup in names(r))
            and method in (None, r.method)
            and town in (None, r.town, r.config["town"])
            and kind in (None, r.kind)
            and repetition in (None, r.repetition)
        )

    given = {"setup": setup, "method": method, "town": town, "kind": kind, "repetition": repetition}
    wanted = ", ".join(f"{k} {v!r}" for k, v in given.items() if v is not None)
    match = [r for r in done if fits(r)]
    if not match:
        towns = len({r.town for r in done}) > 1  # name the town where the store has several
        there = sorted(
            {
                f"{r.town}: " * towns + f"{x} / {r.method}"
                for r in done
                for x in labels.get(r.key, (r.setup,))
            }
        )
        raise StoreError(
            f"{output_dir}: no finished episode of {wanted or 'any kind'}; there are: "
            + ", ".join(there)
        )
    if failed:
        crashed = [r for r in match if r.metrics is not None and r.metrics.failures]
        if not crashed:
            raise StoreError(
                f"{output_dir}: none of the {len(match)} finished episodes of "
                f"{wanted or 'any kind'} failed"
            )
        match = crashed
    order = {"failure": 0, "recall": 1, "baseline": 2}
    return min(match, key=lambda r: (order.get(r.kind, 3), r.repetition, r.key))


def _colour(locs: dict[str, Array], k: int) -> tuple[int, int, int]:
    fused = locs["fused"][k]  # True, False, or None when never offered to the EKF
    if fused is not None and not fused:
        return REJECTED
    position_m, rotation_deg = locs["position_error_3d_m"][k], locs["rotation_error_deg"][k]
    if position_m <= 0.25 and rotation_deg <= 2.0:
        return GOOD
    return FAIR if position_m <= 5.0 and rotation_deg <= 10.0 else WRONG


def record_episode(
    output_dir: str | Path,
    row: EpisodeRow,
    path: str | Path,
    images: bool = False,
    spawn: bool = False,
) -> Path:
    """Write the rerun recording of ``row`` (an episode stored in ``output_dir``) to ``path``;
    ``spawn`` also opens the viewer."""
    if row.metrics is None:
        raise StoreError(f"episode {row.key} ended in an error: it has no drive to record")
    rr = _rerun()
    output_dir, path = Path(output_dir), Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tr = read_episode_table(output_dir, row.key, "trajectory")
    locs = localizations(output_dir, row.key)
    rec = rr.RecordingStream("vlocbench", recording_id=row.key)
    if spawn:
        rec.spawn()
    rec.save(str(path))
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    town = town_named(row.config["town"])
    _log_town(rr, rec, town, route_named(row.config["town"], row.metrics.route_length_m).xy)
    for name, prefix, colour in (("truth", "true", (40, 120, 230)), ("ekf", "ekf", (240, 140, 30))):
        xyz = np.c_[tr[f"{prefix}_x_m"], tr[f"{prefix}_y_m"], np.full(len(tr["time_s"]), 0.1)]
        rec.log(f"{name}/path", rr.LineStrips3D([xyz], colors=[colour]), static=True)
        car = rr.Boxes3D(half_sizes=[CAR_HALF_SIZE_M], centers=[(0, 0, 0.75)], colors=[colour])
        rec.log(f"{name}/car", car, static=True)
    for k, t in enumerate(tr["time_s"]):
        rec.set_time("sim_time", duration=float(t))
        for name, prefix in (("truth", "true"), ("ekf", "ekf")):
            pose = planar_pose(
                tr[f"{prefix}_x_m"][k], tr[f"{prefix}_y_m"][k], tr[f"{prefix}_yaw_rad"][k]
            )
            rec.log(name, rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))
    sites = row.metrics.failure_sites_xy
    if sites:
        causes = list(row.metrics.failure_causes)  # one per failure, in order
        points = rr.Points3D(
            [(x, y, 1.0) for x, y in sites],
            radii=1.5,
            colors=[WRONG],
            labels=causes if len(causes) == len(sites) else None,
        )
        rec.log("failures", points, static=True)
    if locs:
        _log_localizations(rr, rec, row, locs, images)
    rec.flush()
    return path


def _log_town(rr: Any, rec: Any, town: Town, route_xy: Array) -> None:
    centres, halves = [], []
    for b in town.buildings:
        x0, y0, x1, y1 = b.rect
        centres.append(((x0 + x1) / 2, (y0 + y1) / 2, b.height_m / 2))
        halves.append(((x1 - x0) / 2, (y1 - y0) / 2, b.height_m / 2))
    buildings = rr.Boxes3D(centers=centres, half_sizes=halves, colors=[(170, 160, 150)])
    rec.log("town/buildings", buildings, static=True)
    route = np.c_[route_xy, np.full(len(route_xy), 0.05)]
    rec.log("route", rr.LineStrips3D([route], colors=[(90, 90, 90)]), static=True)


def _log_localizations(
    rr: Any, rec: Any, row: EpisodeRow, locs: dict[str, Array], images: bool
) -> None:
    camera = episode_camera(row.config)
    vehicle_from_cam = camera.extrinsics.vehicle_from_cam()
    intrinsics = camera.intrinsics
    focal_px = camera_model(camera).K[0, 0]
    renderer = QueryRenderer(row.config) if images else None
    gallery = _gallery_of(row) if images else None
    world_from_vehicle = estimate_poses(locs, np.arange(len(locs["time_s"])))
    for k, t in enumerate(locs["time_s"]):
        rec.set_time("sim_time", duration=float(t))
        ok = bool(locs["success"][k])
        if ok:
            world_from_cam = world_from_vehicle[k] @ vehicle_from_cam
            rec.log(
                "localization",
                rr.Transform3D(translation=world_from_cam[:3, 3], mat3x3=world_from_cam[:3, :3]),
            )
            frustum = rr.Pinhole(
                focal_length=float(focal_px),
                width=intrinsics.width,
                height=intrinsics.height,
                image_plane_distance=3.0,
                color=_colour(locs, k),
                line_width=0.05,
            )
            rec.log("localization/camera", frustum)
            position_m, rotation_deg = (
                float(locs["position_error_3d_m"][k]),
                float(locs["rotation_error_deg"][k]),
            )
            rec.log("errors/position_m", rr.Scalars(position_m))
            rec.log("errors/rotation_deg", rr.Scalars(rotation_deg))
            fused = locs["fused"][k]
            text = f"answer: {position_m:.2f} m, {rotation_deg:.1f} deg" + (
                "" if fused is None else f", fused: {bool(fused)}"
            )
        else:
            text = f"no answer: {locs['reason'][k]}"
        rec.log("localization/log", rr.TextLog(text, level="INFO" if ok else "WARN"))
        if renderer is not None:
            truth = (locs["true_x_m"][k], locs["true_y_m"][k], locs["true_yaw_rad"][k])
            rec.log("localization/camera/image", _thumbnail(rr, renderer.image(*truth, float(t))))
        names = locs.get("retrieved_images")
        if gallery is not None and names is not None:
            for j, name in enumerate(list(names[k])[:RETRIEVED_SHOWN]):
                rec.log(f"retrieved/{j}", _thumbnail(rr, gallery.load_image(str(name))))
    if renderer is not None:
        renderer.close()


def _thumbnail(rr: Any, image: Image) -> Any:
    """An image at half size as JPEG: a drive's worth of queries stays a few tens of MB."""
    import cv2

    h, w = image.shape[:2]
    small = cv2.resize(image, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    return rr.Image(small).compress(jpeg_quality=80)


def _gallery_of(row: EpisodeRow) -> Any:
    from vlocbench.loc.gallery import Gallery
    from vlocbench.loc.mapping import map_info

    map_dir = row.config.get("map_dir")
    return Gallery.load(map_info(map_dir)[1]) if map_dir else None
