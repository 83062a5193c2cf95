"""Gallery capture: drive a route on ground truth and take an image every ``spacing_m`` metres."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from vlocbench.bench.visual import camera_model
from vlocbench.loc.gallery import Gallery, GalleryWriter
from vlocbench.nav import (
    ControllerConfig,
    LocalPlanner,
    ProgressTracker,
    VehicleController,
    WaypointPath,
)
from vlocbench.sim import Camera, Simulator


def capture_gallery(
    sim: Simulator,
    path: WaypointPath,
    cameras: tuple[Camera, ...],
    out_dir: str | Path,
    spacing_m: float = 2.0,
    speed_mps: float = 8.0,
    progress: Callable[[int], None] | None = None,
) -> Gallery:
    """Drive ``path`` at ``speed_mps`` on the true pose (the paper's gallery drive), rendering every
    camera each ``spacing_m`` of distance; writes a gallery folder with the exact camera poses."""
    sim.reset(float(path.xy[0, 0]), float(path.xy[0, 1]), float(path.yaw_rad[0]))
    planner = LocalPlanner(path)
    controller = VehicleController(ControllerConfig(target_speed_mps=speed_mps), sim.dt_s)
    tracker = ProgressTracker(path)
    writer = GalleryWriter(out_dir)
    travelled_m, next_m, shots = 0.0, 0.0, 0
    limit_s = 3 * path.length_m / speed_mps + 60
    while not tracker.finished and sim.state.time_s < limit_s:
        s = sim.state
        if travelled_m >= next_m - 1e-9:
            for frame in sim.render(cameras):
                writer.add(
                    f"{shots:05d}_{frame.camera.name}.png",
                    frame.image,
                    frame.camera.name,
                    camera_model(frame.camera),
                    frame.world_from_cam,
                )
            shots += 1
            next_m += spacing_m
            if progress:
                progress(shots)
        target = planner.step(np.array([s.x_m, s.y_m]), s.speed_mps)
        cmd = controller.step(s.x_m, s.y_m, s.yaw_rad, s.speed_mps, target.xy, target.remaining_m)
        new = sim.step(cmd).state
        travelled_m += float(np.hypot(new.x_m - s.x_m, new.y_m - s.y_m))
        tracker.update(np.array([new.x_m, new.y_m]))
    return writer.close()
