"""Visual localization in the episode loop: a map-based localizer behind the ``Localizer`` protocol.

The cameras are one rig whose frame is the vehicle's: each is localized on its own, then one
generalized PnP over all their correspondences gives ``world_from_vehicle`` directly (or the best
camera's pose through its mounting, ``world_from_cam @ cam_from_vehicle``, when that has more
inliers or only one camera found its place).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from vlocbench.bench.localizer import LocalizationQuery, PoseEstimate
from vlocbench.geometry import PLANAR_OF_POSE, invert_pose
from vlocbench.loc.gallery import CameraModel
from vlocbench.loc.localizer import LocalizerConfig, MapLocalizer, RigResult
from vlocbench.sim import Camera, Frame

if TYPE_CHECKING:
    from vlocbench.bench.methods import MethodContext


def camera_model(camera: Camera) -> CameraModel:
    i = camera.intrinsics
    return CameraModel(i.width, i.height, i.K)


class VisualLocalizer:
    """Localizes the images of ``cameras`` against the map in ``map_dir``. ``gallery_camera`` took
    the map's images (default: the first of ``cameras`` as configured, before a viewpoint change):
    its mount puts each retrieved image's car in place, for the place-recognition figures."""

    uses_ground_truth = False

    def __init__(
        self,
        map_dir: str | Path,
        cameras: Sequence[Camera],
        config: LocalizerConfig | None = None,
        name: str | None = None,
        gallery_camera: Camera | None = None,
    ) -> None:
        self.localizer = MapLocalizer(map_dir, config)
        self._cameras = tuple(cameras)
        self.name = name or Path(map_dir).name
        mount = (gallery_camera or self._cameras[0]).extrinsics.vehicle_from_cam()
        self._cam_from_gallery_vehicle = invert_pose(mount)

    @property
    def cameras(self) -> Sequence[Camera]:
        return self._cameras

    def reset(self, seed: int) -> None:
        """Stateless, and its RANSAC is seeded by its config."""

    def close(self) -> None:
        """Its map is freed with it."""

    def localize(self, query: LocalizationQuery) -> PoseEstimate:
        """All cameras as one rig (the vehicle frame): a generalized PnP over their matches."""
        start = time.perf_counter()
        if not query.frames:
            return PoseEstimate.failure("no images", 0.0)
        result = self.localizer.localize_rig(
            [frame.image for frame in query.frames],
            [camera_model(frame.camera) for frame in query.frames],
            [frame.camera.extrinsics.vehicle_from_cam() for frame in query.frames],
            query.prior_world_from_vehicle,
        )
        # what the method takes, a share of it done by another localizer on a shared drive included
        elapsed = time.perf_counter() - start + result.shared_s
        # where the gallery's car stood for each of the first camera's retrieved images (not where
        # the query's mount would put it: a raised or tilted camera would move it by metres)
        ranked = result.cameras[0].ranked_world_from_cam @ self._cam_from_gallery_vehicle
        attempt: dict[str, Any] = {  # what a failure reports too
            "ranked_xyz_m": ranked[:, :3, 3],
            "retrieved": tuple(name for r in result.cameras for name in r.retrieved),
            "stage_s": dict(result.seconds),
            "correspondences": sum(r.num_correspondences for r in result.cameras),
        }
        if not result.success:
            return PoseEstimate.failure(result.reason, elapsed, **attempt)
        assert result.world_from_rig is not None
        return PoseEstimate(
            True,
            result.world_from_rig,
            self._covariance(result, query.frames),
            elapsed,
            result.reason,
            inliers=result.num_inliers,
            camera="rig" if result.generalized else query.frames[result.camera].camera.name,
            fallback=not result.generalized and result.cameras[result.camera].fallback,
            **attempt,
        )

    def _covariance(self, result: RigResult, frames: Sequence[Frame]) -> NDArray[np.float64] | None:
        """(3, 3) over the vehicle's (x, y, yaw) with ``localizer.covariance: estimate``: the PnP's
        of the camera whose pose answered, through its mounting; None (the filter's default) when
        fixed, and for a generalized rig pose, whose PnP gives none."""
        config = self.localizer.config
        if config.covariance == "fixed" or result.generalized:
            return None
        mount = frames[result.camera].camera.extrinsics.vehicle_from_cam()
        full = result.cameras[result.camera].covariance_of(
            invert_pose(mount), config.pixel_noise_px
        )
        return None if full is None else full[np.ix_(PLANAR_OF_POSE, PLANAR_OF_POSE)]


def map_localizer(context: MethodContext, config: LocalizerConfig) -> VisualLocalizer:
    """The ``map`` kind of :data:`~vlocbench.bench.methods.LOCALIZER_KINDS`."""
    if context.map_dir is None:
        raise ValueError(f"{context.name}: the map kind needs its map folder")
    return VisualLocalizer(
        context.map_dir, context.cameras, config, context.name, context.gallery_camera
    )
