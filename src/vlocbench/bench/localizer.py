"""The interface between the episode loop and a localization method, and reference localizers.

A localizer receives the images of its camera rig taken at one instant (and, for pose-prior
methods, the EKF's estimate at that instant) and answers with the vehicle's pose or a failure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from vlocbench.config import require
from vlocbench.errors import UnknownNameError
from vlocbench.geometry import planar_pose
from vlocbench.interfaces import Array
from vlocbench.loc.localizer import COVARIANCES
from vlocbench.sim import Camera, Frame

if TYPE_CHECKING:
    from vlocbench.bench.methods import MethodContext


@dataclass(frozen=True)
class LocalizationQuery:
    """What a localizer sees at ``time_s``.

    ``frames``: one per camera of the localizer's rig, rendered at the true pose.
    ``prior_world_from_vehicle``: (4, 4) the EKF's estimate at ``time_s``.
    ``true_world_from_vehicle``: (4, 4) the true pose; set only for localizers that declare
    ``uses_ground_truth`` (reference methods such as the oracle), ``None`` for every other.
    """

    time_s: float
    frames: tuple[Frame, ...]
    prior_world_from_vehicle: Array
    true_world_from_vehicle: Array | None = None


@dataclass(frozen=True)
class PoseEstimate:
    """A localizer's answer. On success ``world_from_vehicle`` is (4, 4); ``covariance`` (3, 3)
    over (x, y, yaw) or ``None`` for the EKF's default. On failure ``reason`` says why.
    ``compute_time_s``: the method's own time (wall clock). The rest is what a method may report
    of its attempt (a failure too), for the records and the reports; every field is optional."""

    success: bool
    world_from_vehicle: Array | None = None
    covariance: Array | None = None
    compute_time_s: float = 0.0
    reason: str = ""
    inliers: int = 0  # PnP inliers of the answer (0: none, or not reported)
    correspondences: int = 0  # 2D-3D correspondences PnP was given
    camera: str = ""  # the camera whose pose answered, "rig" for one PnP over all of them
    fallback: bool = False  # answered by the localizer's fallback (e.g. the best single image)
    retrieved: tuple[str, ...] = ()  # the gallery images retrieved, best first, camera by camera
    # (R, 3) where the gallery's vehicle stood for each of the first camera's retrieved images
    ranked_xyz_m: Array | None = None
    stage_s: Mapping[str, float] = field(default_factory=dict)  # time per stage (features, ...)

    @classmethod
    def failure(cls, reason: str, compute_time_s: float = 0.0, **attempt: Any) -> PoseEstimate:
        """No pose; ``attempt``: any of the optional fields, as far as the method got."""
        return cls(False, compute_time_s=compute_time_s, reason=reason, **attempt)

    def retrieval_distances_m(self, world_from_vehicle: Array) -> Array:
        """(R,) distances from the true vehicle pose (4, 4) to where the gallery's vehicle stood
        for each of the retrieval's best images (``ranked_xyz_m``), best first; (0,) for a
        localizer without retrieval."""
        if self.ranked_xyz_m is None:
            return np.zeros(0)
        ranked_xyz = np.asarray(self.ranked_xyz_m, np.float64).reshape(-1, 3)
        return np.linalg.norm(ranked_xyz - world_from_vehicle[:3, 3], axis=1)


@runtime_checkable
class Localizer(Protocol):
    """What the episode loop needs of a localization method. ``uses_ground_truth``: its queries
    carry the true pose (reference methods such as the oracle; a method under test says False)."""

    name: str
    uses_ground_truth: bool

    @property
    def cameras(self) -> Sequence[Camera]:
        """The rig whose images each query carries (empty: no rendering)."""
        ...

    def reset(self, seed: int) -> None:
        """A new episode starts (drop sequential state; reseed any randomness)."""
        ...

    def localize(self, query: LocalizationQuery) -> PoseEstimate: ...

    def close(self) -> None:
        """Release what it holds (a map, a connection); the runner calls it when done."""
        ...


def planar_of(world_from_vehicle: Array) -> tuple[float, float, float]:
    """(x m, y m, yaw rad) of a (4, 4) vehicle pose."""
    return (
        float(world_from_vehicle[0, 3]),
        float(world_from_vehicle[1, 3]),
        float(np.arctan2(world_from_vehicle[1, 0], world_from_vehicle[0, 0])),
    )


@dataclass(frozen=True)
class OracleConfig:
    position_sigma_m: float = 0.0
    yaw_sigma_deg: float = 0.0
    failure_probability: float = 0.0
    # "estimate": each answer carries its noise's covariance (at least 1e-4 a term); "fixed": none,
    # so the filter takes its default, as it does the paper's localizer's (0.1 on x, y and yaw)
    covariance: str = "estimate"

    def __post_init__(self) -> None:
        require(self.position_sigma_m >= 0, "oracle.position_sigma_m", "must be >= 0")
        require(self.yaw_sigma_deg >= 0, "oracle.yaw_sigma_deg", "must be >= 0")
        require(
            0 <= self.failure_probability <= 1, "oracle.failure_probability", "must be in [0, 1]"
        )
        if self.covariance not in COVARIANCES:
            raise UnknownNameError("oracle.covariance", self.covariance, COVARIANCES)


class OracleLocalizer:
    """Reference method: the true pose with seeded Gaussian noise, failing with a set probability.

    Answers how good localization must be for navigation, with no images rendered.
    """

    name = "oracle"
    uses_ground_truth = True

    def __init__(self, config: OracleConfig | None = None) -> None:
        self.config = config or OracleConfig()
        self.reset(0)

    @property
    def cameras(self) -> Sequence[Camera]:
        return ()

    def reset(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def close(self) -> None:
        """Holds nothing."""

    def localize(self, query: LocalizationQuery) -> PoseEstimate:
        c = self.config
        if query.true_world_from_vehicle is None:
            raise ValueError("the oracle needs the true pose in its queries")
        noise = self.rng.standard_normal(3)
        if self.rng.random() < c.failure_probability:
            return PoseEstimate.failure("simulated failure")
        x, y, yaw = planar_of(query.true_world_from_vehicle)
        pose = planar_pose(
            x + c.position_sigma_m * noise[0],
            y + c.position_sigma_m * noise[1],
            yaw + np.radians(c.yaw_sigma_deg) * noise[2],
        )
        if c.covariance == "fixed":
            return PoseEstimate(True, pose)
        var = np.array([c.position_sigma_m**2] * 2 + [np.radians(c.yaw_sigma_deg) ** 2])
        return PoseEstimate(True, pose, np.diag(np.maximum(var, 1e-4)))


def oracle_localizer(context: MethodContext, config: OracleConfig) -> OracleLocalizer:
    """The ``oracle`` kind of :data:`~vlocbench.bench.methods.LOCALIZER_KINDS`."""
    oracle = OracleLocalizer(config)
    oracle.name = context.name
    return oracle
