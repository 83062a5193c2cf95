"""Image retrieval: global descriptors compared by cosine similarity, or gallery poses near a prior.

A global descriptor may learn from the gallery first (VLAD learns its vocabulary there); its learned
state is saved with the map.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import cv2
import numpy as np
from numpy.typing import NDArray

from vlocbench.loc.features import Features

Descriptor = NDArray[np.float32]


@runtime_checkable
class GlobalDescriptor(Protocol):
    """One L2-normalized vector per image; similar places give similar vectors."""

    name: str

    def fit(self, gallery_features: Sequence[Features]) -> None:
        """Learn from the gallery's local features (a no-op for pretrained descriptors)."""
        ...

    def state(self) -> dict[str, np.ndarray]:
        """What ``fit`` learned, to save with the map."""
        ...

    def load_state(self, state: dict[str, np.ndarray]) -> None: ...

    def describe(self, image: NDArray[np.uint8], features: Features) -> Descriptor:
        """(D,) float32 with unit norm."""
        ...


def _normalize(v: np.ndarray) -> Descriptor:
    n = float(np.linalg.norm(v))
    return (v / n if n > 0 else v).astype(np.float32)


def _as_float(descriptors: np.ndarray) -> NDArray[np.float32]:
    """Float vectors of float descriptors, or of binary ones (bits as +-1)."""
    if descriptors.dtype == np.uint8:
        return np.unpackbits(descriptors, axis=1).astype(np.float32) * 2 - 1
    return descriptors.astype(np.float32)


class Vlad:
    """VLAD (Jegou et al.) over the local descriptors, with a k-means vocabulary learned from the
    gallery itself; intra-normalized, signed square root, L2-normalized."""

    def __init__(
        self, clusters: int = 64, samples: int = 100_000, seed: int = 0, name: str = "vlad"
    ):
        self.name, self.clusters, self.samples, self.seed = name, clusters, samples, seed
        self.centers: NDArray[np.float32] | None = None

    def fit(self, gallery_features: Sequence[Features]) -> None:
        desc = np.concatenate([_as_float(f.descriptors) for f in gallery_features if len(f)])
        rng = np.random.default_rng(self.seed)
        if len(desc) > self.samples:
            desc = desc[rng.choice(len(desc), self.samples, replace=False)]
        k = min(self.clusters, len(desc))
        cv2.setRNGSeed(self.seed)
        criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-4)
        # no initial labels (None), which OpenCV's stub does not allow for
        _, _, centers = cv2.kmeans(desc, k, None, criteria, 2, cv2.KMEANS_PP_CENTERS)  # type: ignore[call-overload]
        self.centers = centers.astype(np.float32)

    def state(self) -> dict[str, np.ndarray]:
        assert self.centers is not None, "fit() first"
        return {"centers": self.centers}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        self.centers = np.asarray(state["centers"], dtype=np.float32)

    def describe(self, image: NDArray[np.uint8], features: Features) -> Descriptor:
        if self.centers is None:
            raise RuntimeError("VLAD has no vocabulary: fit() it on a gallery or load its state")
        k, d = self.centers.shape
        if not len(features):
            return np.zeros(k * d, np.float32)
        x = _as_float(features.descriptors)
        d2 = (x**2).sum(1)[:, None] - 2 * x @ self.centers.T + (self.centers**2).sum(1)[None]
        nearest = np.argmin(d2, axis=1)
        residuals = np.zeros((k, d), np.float32)
        np.add.at(residuals, nearest, x - self.centers[nearest])
        residuals /= np.maximum(np.linalg.norm(residuals, axis=1, keepdims=True), 1e-12)
        v = residuals.ravel()
        return _normalize(np.sign(v) * np.sqrt(np.abs(v)))


def top_k(query: Descriptor, gallery: NDArray[np.float32], k: int) -> NDArray[np.int64]:
    """Indices of the ``k`` gallery rows (N, D) most similar to ``query`` (D,), best first."""
    sims = gallery @ query
    k = min(k, len(sims))
    idx = np.argpartition(-sims, k - 1)[:k]
    return idx[np.lexsort((idx, -sims[idx]))]


def nearest_poses(
    world_from_cams: NDArray[np.float64],
    world_from_cam: NDArray[np.float64],
    k: int,
    max_angle_deg: float = 60.0,
) -> NDArray[np.int64]:
    """The ``k`` gallery cameras (N, 4, 4) closest to a pose (4, 4) among those looking within
    ``max_angle_deg`` of its direction, best first (pose-prior retrieval and mapping pairs)."""
    centres = world_from_cams[:, :3, 3]
    dist = np.linalg.norm(centres - world_from_cam[:3, 3], axis=1)
    cos = world_from_cams[:, :3, 2] @ world_from_cam[:3, 2]
    dist = np.where(cos >= np.cos(np.radians(max_angle_deg)), dist, np.inf)
    order = np.lexsort((np.arange(len(dist)), dist))
    return order[: min(k, int(np.isfinite(dist).sum()))]
