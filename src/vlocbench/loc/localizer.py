"""The hierarchical localizer: retrieval, covisibility clusters, matching, PnP (hloc's pipeline).

One query image with its camera model -> the gallery images most like it (top-k by global
descriptor, or nearest to a prior pose) -> clusters of those that see common 3D points -> local
matches against each retrieved image -> 2D-3D correspondences -> PnP with LO-RANSAC per cluster ->
the cluster with the most inliers wins. A failed PnP is a failure with its reason, never a silent
fall-back to the retrieved image's pose (``fallback_to_retrieval`` makes that explicit).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vlocbench.config import ADDED_OPTION, require
from vlocbench.errors import LocalizationError, UnknownNameError
from vlocbench.geometry import covariance_through_offset, invert_pose, skew
from vlocbench.loc.features import Features, check_image, extract_timed
from vlocbench.loc.gallery import CameraModel
from vlocbench.loc.mapping import FeatureStore, colmap_camera, map_info, pose_of, rigid_of
from vlocbench.loc.native import pycolmap, quiet_pycolmap
from vlocbench.loc.registry import (
    build_features,
    build_matcher,
    build_retrieval,
)
from vlocbench.loc.retrieval import nearest_poses, top_k

MIN_PNP_POINTS = 4  # P3P's minimal sample and one point to choose among its solutions


RETRIEVAL_SOURCES = ("map", "pose-prior")  # LocalizerConfig.retrieval
# LocalizerConfig.covariance: "fixed", none of the answer's own (the filter's default, the paper's
# 0.1); "estimate", the PnP refinement's for ``pixel_noise_px`` of image noise
COVARIANCES = ("fixed", "estimate")


@dataclass(frozen=True)
class LocalizerConfig:
    top_k: int = 5
    ransac_max_error_px: float = 12.0
    # 0: every pose PnP returns is an answer, as hloc's and the paper's localizer publish it;
    # > 0 (vlocbench's option, 12 before): fewer inliers is a failure
    min_inliers: int = 0
    ransac_seed: int = 0  # RANSAC is seeded: the same query gives the same pose
    prior_max_angle_deg: float = 60.0  # pose-prior retrieval: gallery views within this angle
    fallback_to_retrieval: bool = False  # on failure, answer the best retrieved image's pose
    # > 0: match retrieved images one at a time (best first), re-running PnP as correspondences
    # accumulate, and stop once a pose has this many inliers; saves most of the matching time of
    # slow matchers (LightGlue). 0: match every retrieved image, one PnP per cluster.
    confident_inliers: int = 0
    # "map": the map's own retrieval; "pose-prior": the map images nearest the prior pose instead
    # (sequential localization with any map; with the true pose as prior, the local features alone)
    retrieval: str = field(default="map", metadata=ADDED_OPTION)
    # what covariance an answer carries (COVARIANCES); "estimate" assumes this much image noise
    covariance: str = field(default="fixed", metadata=ADDED_OPTION)
    pixel_noise_px: float = field(default=1.0, metadata=ADDED_OPTION)

    def __post_init__(self) -> None:
        require(self.top_k >= 1, "localizer.top_k", "must be >= 1")
        require(self.ransac_max_error_px > 0, "localizer.ransac_max_error_px", "must be > 0")
        require(
            self.min_inliers == 0 or self.min_inliers >= MIN_PNP_POINTS,
            "localizer.min_inliers",
            f"must be 0 (any PnP answer) or >= {MIN_PNP_POINTS}",
        )
        require(self.confident_inliers >= 0, "localizer.confident_inliers", "must be >= 0")
        if self.retrieval not in RETRIEVAL_SOURCES:
            raise UnknownNameError("localizer.retrieval", self.retrieval, RETRIEVAL_SOURCES)
        if self.covariance not in COVARIANCES:
            raise UnknownNameError("localizer.covariance", self.covariance, COVARIANCES)
        require(self.pixel_noise_px > 0, "localizer.pixel_noise_px", "must be > 0")

    @property
    def min_points(self) -> int:
        """Correspondences needed to try PnP at all."""
        return max(self.min_inliers, MIN_PNP_POINTS)


def _unique_rows(rows: NDArray[np.int64]) -> NDArray[np.int64]:
    """``rows`` (M, 2) without repeats, each kept where it first appears."""
    _, first = np.unique(rows, axis=0, return_index=True)
    return rows[np.sort(first)]


def world_covariance(
    cam_from_world: NDArray[np.float64], cam_from_world_covariance: NDArray[np.float64]
) -> NDArray[np.float64]:
    """pycolmap's (6, 6) PnP covariance of ``cam_from_world`` (4, 4) as the covariance of
    ``world_from_cam``: (position in the world, m; world-side rotation vector, rad).

    pycolmap's is over (quaternion tangent, translation), the rotation perturbed on the left
    (``R' = Exp(2 d) R``: Ceres's quaternion tangent is half the rotation angle) and the
    translation added (``t' = t + v``). The camera centre ``c = -R^T t`` then moves by
    ``-R^T [t]x w - R^T v`` and the world-side rotation of ``world_from_cam`` is ``-R^T w``.
    """
    rotation, translation = cam_from_world[:3, :3], cam_from_world[:3, 3]
    jacobian = np.zeros((6, 6))  # (centre, world rotation) from (half-angle d, v)
    jacobian[:3, :3] = -2.0 * rotation.T @ skew(translation)
    jacobian[:3, 3:] = -rotation.T
    jacobian[3:, :3] = -2.0 * rotation.T
    return jacobian @ np.asarray(cam_from_world_covariance) @ jacobian.T


RANKED = 10  # retrieval ranks kept per query: place recognition's Recall@1, 5 and 10


@dataclass(frozen=True, kw_only=True)
class QueryResult:
    """``world_from_cam`` (4, 4) on success; ``world_from_cam_covariance`` (6, 6) from the PnP
    refinement for 1 px of image noise, over (camera position x, y, z in the world, m; rotation
    vector of a small rotation on the world side, rad), see :func:`world_covariance`; times per
    stage in seconds; ``reason`` on failure."""

    success: bool
    world_from_cam: NDArray[np.float64] | None = None
    num_inliers: int = 0
    num_correspondences: int = 0
    retrieved: tuple[str, ...] = ()
    # the retrieval's best max(top_k, RANKED) map images' poses (R, 4, 4), best first: what the
    # place-recognition metric scores
    ranked_world_from_cam: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4, 4)))
    cluster: tuple[str, ...] = ()
    world_from_cam_covariance: NDArray[np.float64] | None = None
    seconds: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    fallback: bool = False
    # of ``seconds``, those another localizer spent for this one (features extracted once for
    # localizers that share a drive and an extractor: features.shared_extraction)
    shared_s: float = 0.0

    def covariance_of(
        self, cam_from_body: NDArray[np.float64], pixel_noise_px: float
    ) -> NDArray[np.float64] | None:
        """(6, 6) covariance of ``world_from_cam @ cam_from_body`` (a body the camera is mounted
        on, (4, 4) ``cam_from_body``) for ``pixel_noise_px`` of image noise, in the convention of
        ``world_from_cam_covariance``; None where the PnP gave none."""
        if self.world_from_cam is None or self.world_from_cam_covariance is None:
            return None
        return pixel_noise_px**2 * covariance_through_offset(
            self.world_from_cam_covariance, self.world_from_cam, cam_from_body
        )


@dataclass(frozen=True, kw_only=True)
class RigResult:
    """A rig's query: ``world_from_rig`` (4, 4) on success, from one generalized PnP over the
    cameras' correspondences (or the best camera's own pose when that has more inliers, or only one
    camera found its place); ``cameras``: each camera's own result."""

    success: bool
    world_from_rig: NDArray[np.float64] | None
    num_inliers: int
    camera: int  # the camera whose own pose it is; -1: the generalized PnP's (or none)
    cameras: tuple[QueryResult, ...]
    seconds: dict[str, float]
    reason: str = ""

    @property
    def generalized(self) -> bool:
        return self.success and self.camera < 0

    @property
    def shared_s(self) -> float:
        """Of ``seconds``, those another localizer spent (see :attr:`QueryResult.shared_s`)."""
        return sum(r.shared_s for r in self.cameras)


@dataclass(frozen=True)
class _Correspondences:
    points2D: NDArray[np.float64]  # (M, 2) COLMAP pixel coordinates
    points3D: NDArray[np.float64]  # (M, 3) world


@dataclass(frozen=True)
class _Pose:
    """The best PnP answer so far: its inliers, pycolmap's answer, the cluster's images."""

    inliers: int
    answer: dict | None
    cluster: list[int]
    corr: _Correspondences | None


@dataclass
class _MapImage:
    name: str
    world_from_cam: NDArray[np.float64]
    features: Features  # only the keypoints with a 3D point
    point_ids: NDArray[np.int64]  # (N,) their 3D points


class MapLocalizer:
    """Localizes images against a map built by :func:`vlocbench.loc.mapping.build_map`."""

    def __init__(self, map_dir: str | Path, config: LocalizerConfig | None = None) -> None:
        quiet_pycolmap()  # Ceres warns of every degenerate pose covariance
        self.map_dir = Path(map_dir)
        self.config = config or LocalizerConfig()
        self.method, self.gallery_dir = map_info(self.map_dir)  # what the map was built with
        try:
            rec = pycolmap.Reconstruction(self.map_dir / "sfm")
        except Exception as exc:  # pycolmap raises plain exceptions for unreadable models
            raise LocalizationError(
                f"the model in {self.map_dir / 'sfm'} is unreadable: {exc}"
            ) from None
        if rec.num_points3D() == 0:
            raise LocalizationError(f"the map in {self.map_dir} has no 3D points")
        self.extractor = build_features(self.method.features)
        self.matcher = build_matcher(self.method.matcher)
        self.descriptor = build_retrieval(self.method.retrieval)
        store = FeatureStore(self.map_dir / "features.h5")
        ids = sorted(rec.images)
        self.images: list[_MapImage] = []
        with store.reading() as read:
            for image_id in ids:
                im = rec.images[image_id]
                feats = read(im.name)
                p3d = np.array(
                    [p.point3D_id if p.has_point3D() else -1 for p in im.points2D], np.int64
                )
                if len(p3d) != len(feats):
                    raise LocalizationError(
                        f"{store.path} does not match the model for {im.name!r}"
                    )
                keep = np.flatnonzero(p3d >= 0)
                pose = invert_pose(pose_of(im.cam_from_world()))
                self.images.append(_MapImage(im.name, pose, feats.subset(keep), p3d[keep]))
        self.points3D = {pid: p.xyz for pid, p in rec.points3D.items()}
        self.poses = np.stack([m.world_from_cam for m in self.images])
        self.global_descriptors: NDArray[np.float32] | None = None
        if self.descriptor is not None:
            import h5py

            with np.load(self.map_dir / "retrieval.npz") as state:
                self.descriptor.load_state(dict(state))
            with h5py.File(self.map_dir / "global.h5", "r") as f:
                self.global_descriptors = np.stack([f[m.name][()] for m in self.images])

    @property
    def needs_prior(self) -> bool:
        return self.descriptor is None or self.config.retrieval == "pose-prior"

    def _retrieve(
        self,
        image: NDArray[np.uint8],
        feats: Features,
        prior_world_from_cam: NDArray[np.float64] | None,
    ) -> NDArray[np.int64]:
        """The best ``max(top_k, RANKED)`` map images, best first."""
        c, k = self.config, max(self.config.top_k, RANKED)
        if self.needs_prior:
            if prior_world_from_cam is None:
                raise LocalizationError("pose-prior retrieval needs a prior pose")
            return nearest_poses(self.poses, prior_world_from_cam, k, c.prior_max_angle_deg)
        assert self.descriptor is not None and self.global_descriptors is not None
        return top_k(self.descriptor.describe(image, feats), self.global_descriptors, k)

    def _clusters(self, retrieved: NDArray[np.int64]) -> list[list[int]]:
        """Connected groups of retrieved images that share 3D points, in retrieval order."""
        sets = {int(i): set(self.images[i].point_ids.tolist()) for i in retrieved}
        clusters: list[list[int]] = []
        for i in (int(i) for i in retrieved):
            joined = [c for c in clusters if any(sets[i] & sets[j] for j in c)]
            merged = [i] + [j for c in joined for j in c]
            clusters = [c for c in clusters if c not in joined] + [merged]
        order = {int(i): k for k, i in enumerate(retrieved)}
        return sorted(
            (sorted(c, key=order.__getitem__) for c in clusters), key=lambda c: order[c[0]]
        )

    def localize(
        self,
        image: NDArray[np.uint8],
        camera: CameraModel,
        prior_world_from_cam: NDArray[np.float64] | None = None,
    ) -> QueryResult:
        """Localize one image taken by ``camera``; ``prior_world_from_cam`` for pose-prior maps."""
        return self._solve(image, camera, prior_world_from_cam)[0]

    def _solve(
        self,
        image: NDArray[np.uint8],
        camera: CameraModel,
        prior_world_from_cam: NDArray[np.float64] | None,
    ) -> tuple[QueryResult, _Correspondences | None]:
        """The result, and the 2D-3D correspondences of the winning cluster (None without one)."""
        seconds: dict[str, float] = {}
        image = check_image(image, "query image")
        if image.shape[:2] != (camera.height, camera.width):
            raise LocalizationError(
                f"query image is {image.shape[1]}x{image.shape[0]}, its camera {camera.width}x{camera.height}"
            )
        feats, seconds["features"], shared_s = extract_timed(
            self.extractor, self.method.features, image
        )
        result, corr = self._answer(image, feats, camera, prior_world_from_cam, seconds)
        return (dataclasses.replace(result, shared_s=shared_s) if shared_s else result), corr

    def _answer(
        self,
        image: NDArray[np.uint8],
        feats: Features,
        camera: CameraModel,
        prior_world_from_cam: NDArray[np.float64] | None,
        seconds: dict[str, float],
    ) -> tuple[QueryResult, _Correspondences | None]:
        """:meth:`_solve` once the image's features are there."""
        c = self.config
        t = time.perf_counter()
        ranked = self._retrieve(image, feats, prior_world_from_cam)
        retrieved = ranked[: c.top_k]
        ranked_poses = self.poses[ranked]
        seconds["retrieval"] = time.perf_counter() - t
        if len(feats) < c.min_points:
            reason = f"only {len(feats)} features in the image"
            return self._failed(retrieved, ranked_poses, seconds, reason), None
        best = self._best_pose(feats, colmap_camera(camera, 1), retrieved, seconds)
        n_corr = 0 if best.corr is None else len(best.corr.points2D)
        if best.answer is None or best.inliers < c.min_inliers:
            reason = (
                f"PnP found {best.inliers} inliers (< {c.min_inliers})"
                if best.answer is not None
                else f"PnP found no pose from {n_corr} correspondences"
            )
            return self._failed(retrieved, ranked_poses, seconds, reason, n_corr), best.corr
        cam_from_world = pose_of(best.answer["cam_from_world"])
        covariance = best.answer.get("covariance")
        return QueryResult(
            success=True,
            world_from_cam=invert_pose(cam_from_world),
            num_inliers=best.inliers,
            num_correspondences=n_corr,
            retrieved=tuple(self.images[i].name for i in retrieved),
            ranked_world_from_cam=ranked_poses,
            cluster=tuple(self.images[i].name for i in best.cluster),
            world_from_cam_covariance=(
                None if covariance is None else world_covariance(cam_from_world, covariance)
            ),
            seconds=seconds,
        ), best.corr

    def _best_pose(
        self,
        feats: Features,
        cam: pycolmap.Camera,
        retrieved: NDArray[np.int64],
        seconds: dict[str, float],
    ) -> _Pose:
        """Match the retrieved images cluster by cluster and solve PnP on each cluster's
        correspondences; the pose with the most inliers wins. A query keypoint matched to the same
        3D point through several images of a cluster is one correspondence, as in hloc's
        ``pose_from_cluster`` and the paper's localizer: a point seen by many retrieved images
        neither counts as several inliers nor weighs more in RANSAC. With ``confident_inliers``,
        PnP runs as each image's matches accumulate and the search stops at a pose that
        confident."""
        c = self.config
        options = pycolmap.AbsolutePoseEstimationOptions()
        options.ransac.max_error = c.ransac_max_error_px
        options.ransac.random_seed = c.ransac_seed
        seconds["matching"] = seconds["pnp"] = 0.0
        progressive = c.confident_inliers > 0
        best = _Pose(0, None, [], None)
        for cluster in self._clusters(retrieved):
            pairs = np.zeros((0, 2), np.int64)  # (query keypoint, 3D point id), each once
            for n, i in enumerate(cluster):
                t = time.perf_counter()
                m = self.matcher.match(feats, self.images[i].features)
                seconds["matching"] += time.perf_counter() - t
                found = np.stack([m[:, 0], self.images[i].point_ids[m[:, 1]]], 1)
                pairs = _unique_rows(np.concatenate([pairs, found.astype(np.int64)]))
                if (not progressive and n < len(cluster) - 1) or len(pairs) < c.min_points:
                    continue
                t = time.perf_counter()
                corr = _Correspondences(
                    feats.keypoints[pairs[:, 0]].astype(np.float64) + 0.5,
                    np.array([self.points3D[p] for p in pairs[:, 1]], np.float64),
                )
                answer = pycolmap.estimate_and_refine_absolute_pose(
                    corr.points2D, corr.points3D, cam, options, return_covariance=True
                )
                seconds["pnp"] += time.perf_counter() - t
                if answer is not None and answer["num_inliers"] > best.inliers:
                    best = _Pose(int(answer["num_inliers"]), answer, cluster[: n + 1], corr)
                if progressive and best.inliers >= c.confident_inliers:
                    return best
        return best

    def localize_rig(
        self,
        images: Sequence[NDArray[np.uint8]],
        cameras: Sequence[CameraModel],
        rig_from_cams: Sequence[NDArray[np.float64]],
        prior_world_from_rig: NDArray[np.float64] | None = None,
    ) -> RigResult:
        """Localize the images taken at one instant by the cameras of a rig (mounted at
        ``rig_from_cams``, each (4, 4)): each camera as :meth:`localize` does, then one
        generalized PnP with LO-RANSAC over the correspondences of every camera's winning cluster,
        so that cameras that see little still add their constraints."""
        if not (len(images) == len(cameras) == len(rig_from_cams) >= 1):
            raise LocalizationError(
                f"a rig query needs one image, camera and mounting per camera; got "
                f"{len(images)}, {len(cameras)} and {len(rig_from_cams)}"
            )
        results, pooled = [], []
        for k, (image, camera, rig_from_cam) in enumerate(zip(images, cameras, rig_from_cams)):
            prior = None if prior_world_from_rig is None else prior_world_from_rig @ rig_from_cam
            result, corr = self._solve(image, camera, prior)
            results.append(result)
            if corr is not None:
                pooled.append((k, corr))
        seconds = {
            stage: sum(r.seconds.get(stage, 0.0) for r in results) for stage in results[0].seconds
        }
        # the best camera's own pose; one from a retrieved image (fallback) only when none has PnP
        found = [(not r.fallback, r.num_inliers, k) for k, r in enumerate(results) if r.success]
        pnp, best_inliers, best_k = max(found, default=(False, 0, -1))
        best_inliers = best_inliers if pnp else 0
        if len(pooled) >= 2:
            t = time.perf_counter()
            generalized = self._generalized_pose(pooled, cameras, rig_from_cams)
            seconds["pnp"] = seconds.get("pnp", 0.0) + time.perf_counter() - t
            if generalized is not None and generalized[1] > best_inliers:
                world_from_rig, inliers = generalized
                return RigResult(
                    success=True,
                    world_from_rig=world_from_rig,
                    num_inliers=inliers,
                    camera=-1,
                    cameras=tuple(results),
                    seconds=seconds,
                )
        if best_k >= 0:
            best = results[best_k]
            assert best.world_from_cam is not None
            world_from_rig = best.world_from_cam @ invert_pose(rig_from_cams[best_k])
            return RigResult(
                success=True,
                world_from_rig=world_from_rig,
                num_inliers=best_inliers,
                camera=best_k,
                cameras=tuple(results),
                seconds=seconds,
                reason=best.reason,
            )
        reason = "; ".join(f"camera {k}: {r.reason}" for k, r in enumerate(results))
        return RigResult(
            success=False,
            world_from_rig=None,
            num_inliers=0,
            camera=-1,
            cameras=tuple(results),
            seconds=seconds,
            reason=reason,
        )

    def _generalized_pose(
        self,
        pooled: list[tuple[int, _Correspondences]],
        cameras: Sequence[CameraModel],
        rig_from_cams: Sequence[NDArray[np.float64]],
    ) -> tuple[NDArray[np.float64], int] | None:
        """(world_from_rig, inliers) of one generalized PnP over the cameras' correspondences
        (camera k's as ``pooled`` (k, correspondences)); None without an answer that has at least
        ``min_inliers``."""
        c = self.config
        options = pycolmap.RANSACOptions()
        options.max_error = c.ransac_max_error_px
        options.random_seed = c.ransac_seed
        answer = pycolmap.estimate_and_refine_generalized_absolute_pose(
            np.concatenate([corr.points2D for _, corr in pooled]),
            np.concatenate([corr.points3D for _, corr in pooled]),
            [k for k, corr in pooled for _ in range(len(corr.points2D))],
            [rigid_of(invert_pose(m)) for m in rig_from_cams],
            [colmap_camera(cam, k + 1) for k, cam in enumerate(cameras)],
            options,
        )
        if answer is None:
            return None
        # its num_inliers can count a 3D point that two cameras see once; the mask counts
        # correspondences, as the single-camera PnP does
        inliers = int(np.sum(answer["inlier_mask"]))
        if inliers < c.min_inliers:
            return None
        return invert_pose(pose_of(answer["rig_from_world"])), inliers

    def _failed(
        self,
        retrieved: NDArray[np.int64],
        ranked_poses: NDArray[np.float64],
        seconds: dict[str, float],
        reason: str,
        n_corr: int = 0,
    ) -> QueryResult:
        names = tuple(self.images[i].name for i in retrieved)
        if self.config.fallback_to_retrieval and len(retrieved):
            pose = self.images[int(retrieved[0])].world_from_cam
            return QueryResult(
                success=True,
                world_from_cam=pose,
                num_correspondences=n_corr,
                retrieved=names,
                cluster=names[:1],
                seconds=seconds,
                reason=reason,
                fallback=True,
                ranked_world_from_cam=ranked_poses,
            )
        return QueryResult(
            success=False,
            num_correspondences=n_corr,
            retrieved=names,
            seconds=seconds,
            reason=reason,
            ranked_world_from_cam=ranked_poses,
        )
