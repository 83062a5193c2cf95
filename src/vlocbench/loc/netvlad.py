"""NetVLAD (Arandjelovic et al. 2016) over EfficientNet-Lite0's last feature map: a place
descriptor trained for changed conditions, as the paper's NetVLAD and AP-GeM were.

The paper's networks ship in no package and nothing may be downloaded at run time, so vlocbench
trains its own head (``vlocbench train-retrieval``, :mod:`vlocbench.bench.retrieval_training`):
the ImageNet backbone stays frozen; a projection of its 1280-D local features to ``D`` dimensions
and ``K`` NetVLAD clusters are learned from generated towns (never a town of an experiment), with
queries under the paper's illumination, weather and viewpoint levels against noon galleries. The
descriptor is (K * D,), intra-normalized per cluster, then L2-normalized.

The weights are a ``.npz`` of four arrays (``proj`` (D, 1280), ``assign`` (K, D), ``bias`` (K,),
``centroids`` (K, D)) and ``meta``, the JSON of how they were trained. The shipped file is in
``vlocbench/loc/data``; the preset names its digest, so new weights make new map and episode keys.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vlocbench.config import require
from vlocbench.errors import ConfigError
from vlocbench.loc.features import Features
from vlocbench.loc.learned import EfficientNetLite0, _inference, _numpy, _torch

PARAMS = ("proj", "assign", "bias", "centroids")
SHIPPED = Path(__file__).parent / "data" / "netvlad_towns.npz"
ASSIGN_SCALE = 10.0  # NetVLAD's alpha: the soft assignment starts near the nearest centroid


def aggregate(params: Mapping[str, Any], fmaps: Any) -> Any:
    """NetVLAD of a batch of feature maps: (B, C, H, W) tensors -> (B, K * D) unit vectors; torch
    tensors throughout, so that training takes its gradient."""
    torch = _torch()
    f = torch.nn.functional
    x = fmaps.float().flatten(2)  # (B, C, N)
    x = f.normalize(torch.einsum("dc,bcn->bdn", params["proj"], x), dim=1)
    logits = torch.einsum("kd,bdn->bkn", params["assign"], x) + params["bias"][None, :, None]
    a = torch.softmax(logits, dim=1)  # (B, K, N)
    v = torch.einsum("bkn,bdn->bkd", a, x) - a.sum(2)[..., None] * params["centroids"][None]
    return f.normalize(f.normalize(v, dim=2).flatten(1), dim=1)


def initial_params(fmaps: Any, dim: int, clusters: int, seed: int = 0) -> dict[str, Any]:
    """The head before training: the projection from a PCA of the local features of ``fmaps``
    ((B, C, H, W)), the centroids from k-means (cosine, 20 rounds) of the projected ones, the
    assignment NetVLAD's initialization from them."""
    torch = _torch()
    generator = torch.Generator().manual_seed(seed)
    channels = fmaps.shape[1]
    require(1 <= dim <= channels, "retrieval.dim", f"must be in [1, {channels}]")
    x = fmaps.float().flatten(2).permute(0, 2, 1).reshape(-1, channels)
    x = x[torch.randperm(len(x), generator=generator)[:20_000]]
    require(len(x) >= clusters, "retrieval.clusters", f"must be at most {len(x)} here")
    _, _, vh = torch.linalg.svd(x - x.mean(0), full_matrices=False)
    proj = vh[:dim].clone()
    xs = torch.nn.functional.normalize(x @ proj.T, dim=1)
    centroids = xs[torch.randperm(len(xs), generator=generator)[:clusters]].clone()
    for _ in range(20):
        label = (xs @ centroids.T).argmax(1)
        for k in range(clusters):
            if (label == k).any():
                centroids[k] = torch.nn.functional.normalize(xs[label == k].mean(0), dim=0)
    return {
        "proj": proj,
        "assign": centroids * ASSIGN_SCALE,
        "bias": -0.5 * ASSIGN_SCALE * (centroids * centroids).sum(1),
        "centroids": centroids.clone(),
    }


def save_weights(path: str | Path, params: Mapping[str, Any], meta: Mapping[str, Any]) -> str:
    """Write the head to ``path`` (.npz); returns the file's digest (16 hex digits)."""
    arrays = {k: params[k].detach().cpu().numpy().astype(np.float32) for k in PARAMS}
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays, meta=np.array(json.dumps(dict(meta), sort_keys=True)))
    return weights_digest(path)


def weights_digest(path: str | Path) -> str:
    """16 hex digits of the file's SHA-256."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def load_weights(path: str | Path) -> tuple[dict[str, NDArray[np.float32]], dict[str, Any]]:
    """The arrays and the training record of a weights file, checked."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: np.asarray(data[k], np.float32) for k in PARAMS}
            meta = json.loads(str(data["meta"]))
    except (OSError, KeyError, ValueError) as exc:
        raise ConfigError("retrieval.weights", f"{path}: not NetVLAD weights ({exc})") from None
    dim, clusters = arrays["proj"].shape[0], arrays["centroids"].shape[0]
    shapes = {"assign": (clusters, dim), "bias": (clusters,), "centroids": (clusters, dim)}
    for k, shape in shapes.items():
        if arrays[k].shape != shape:
            raise ConfigError("retrieval.weights", f"{path}: {k} is {arrays[k].shape}, not {shape}")
    return arrays, meta


class EfficientNetNetVlad:
    """NetVLAD over frozen EfficientNet-Lite0 features, trained on generated towns (module
    docstring): (K * D,) unit vectors, 4096-D for the shipped weights (D = 128, K = 32).

    ``weights``: a file written by ``vlocbench train-retrieval``, or empty for the shipped one;
    ``sha256``: where given, the file's digest must match (the presets name the shipped file's,
    so that maps and episodes are keyed by the weights they were made with).
    """

    def __init__(
        self,
        weights: str = "",
        sha256: str = "",
        width: int = 320,
        device: str = "auto",
        name: str = "netvlad-towns",
    ) -> None:
        torch = _torch()
        path = Path(weights) if weights else SHIPPED
        if not path.is_file():
            raise ConfigError("retrieval.weights", f"{path} does not exist")
        digest = weights_digest(path)
        if sha256 and digest != sha256:
            raise ConfigError(
                "retrieval.sha256",
                f"{path} has digest {digest}, the preset names {sha256}: the weights changed "
                "(name the new digest, which re-keys the maps and episodes made with them)",
            )
        arrays, self.meta = load_weights(path)
        self.name, self.digest = name, digest
        self.backbone = EfficientNetLite0(width, "imagenet", device)
        self.device = self.backbone.device
        self.params = {k: torch.from_numpy(v).to(self.device) for k, v in arrays.items()}

    def fit(self, gallery_features: Sequence[Features]) -> None:
        """Trained beforehand: nothing to learn from the gallery."""

    def state(self) -> dict[str, np.ndarray]:
        return {"digest": np.array(self.digest)}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        if str(state["digest"]) != self.digest:
            raise ConfigError(
                "retrieval", f"the map was described with weights {state['digest']}, not these"
            )

    def describe(self, image: NDArray[np.uint8], features: Features) -> NDArray[np.float32]:
        with _inference():
            return _numpy(aggregate(self.params, self.backbone.feature_map(image))[0])
