"""Visual localization in the episode loop: a map-based localizer behind the ``Localizer`` protocol.

Each camera of the rig is localized on its own; the camera with the most PnP inliers gives the
vehicle pose through its known mounting (``world_from_vehicle = world_from_cam @ cam_from_vehicle``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from vlocbench.bench.localizer import LocalizationQuery, PoseEstimate
from vlocbench.loc.gallery import CameraModel
from vlocbench.loc.localizer import LocalizerConfig, MapLocalizer, QueryResult
from vlocbench.sim import Camera


def camera_model(camera: Camera) -> CameraModel:
    i = camera.intrinsics
    return CameraModel(i.width, i.height, i.K)


class VisualLocalizer:
    """Localizes the images of ``cameras`` against the map in ``map_dir``."""

    uses_ground_truth = False

    def __init__(
        self,
        map_dir: str | Path,
        cameras: Sequence[Camera],
        config: LocalizerConfig | None = None,
        name: str | None = None,
    ) -> None:
        self.localizer = MapLocalizer(map_dir, config)
        self._cameras = tuple(cameras)
        self.name = name or Path(map_dir).name

    @property
    def cameras(self) -> Sequence[Camera]:
        return self._cameras

    def reset(self, seed: int) -> None:
        """Stateless, and its RANSAC is seeded by its config."""

    def localize(self, query: LocalizationQuery) -> PoseEstimate:
        start = time.perf_counter()
        best: tuple[QueryResult, Camera] | None = None
        reasons = []
        for frame in query.frames:
            vehicle_from_cam = frame.camera.extrinsics.vehicle_from_cam()
            prior = query.prior_world_from_vehicle @ vehicle_from_cam
            result = self.localizer.localize(frame.image, camera_model(frame.camera), prior)
            if not result.success:
                reasons.append(f"{frame.camera.name}: {result.reason}")
            elif best is None or result.num_inliers > best[0].num_inliers:
                best = (result, frame.camera)
        elapsed = time.perf_counter() - start
        if best is None:
            return PoseEstimate.failure("; ".join(reasons) or "no images", elapsed)
        result, camera = best
        assert result.world_from_cam is not None
        world_from_vehicle = result.world_from_cam @ np.linalg.inv(
            camera.extrinsics.vehicle_from_cam()
        )
        info = {
            "camera": camera.name,
            "inliers": result.num_inliers,
            "correspondences": result.num_correspondences,
            "retrieved": result.retrieved,
            "seconds": result.seconds,
            "fallback": result.fallback,
        }
        return PoseEstimate(True, world_from_vehicle, None, elapsed, result.reason, info)
