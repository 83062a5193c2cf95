"""Named presets of every localization stage (hloc's ``confs`` style), and plugins by dotted path.

A stage is named by a preset (``sift``, ``nn-ratio``, ``vlad``, ...) or by the dotted path of a
user's class, ``package.module:Class`` (or ``package.module.Class``), built with no arguments.
Presets import their module only when used, so the classic methods never import PyTorch.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from vlocbench.config import require
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.loc.features import FeatureExtractor
from vlocbench.loc.matchers import Matcher
from vlocbench.loc.retrieval import GlobalDescriptor

POSE_PRIOR = "pose-prior"  # retrieval by the prior pose: no global descriptor

FEATURES: dict[str, tuple[str, dict[str, Any]]] = {
    # the paper's SIFT: hloc's DoG (COLMAP's VLFeat SIFT through pycolmap), peak threshold 0.01
    "sift": (
        "vlocbench.loc.features:DogSiftExtractor",
        {"peak_threshold": 0.01, "first_octave": 0},
    ),
    # OpenCV's SIFT (an octave finer, about twice the keypoints), the strongest 2048
    "opencv-sift": (
        "vlocbench.loc.features:SiftExtractor",
        {"max_keypoints": 2048, "contrast_threshold": 0.03},
    ),
    "orb-teblid": ("vlocbench.loc.features:OrbTeblidExtractor", {"max_keypoints": 2048}),
    "aliked": ("vlocbench.loc.learned:AlikedExtractor", {"max_keypoints": 1024}),
    # ALIKED's own mode (and LightGlue's): the keypoints scoring above 0.2, the strongest 1024 of
    # them; a dark image gives fewer (town10: median 1024 at noon, 210 at k = 10)
    "aliked-threshold": (
        "vlocbench.loc.learned:AlikedExtractor",
        {"max_keypoints": 1024, "detection_threshold": 0.2},
    ),
    "disk": ("vlocbench.loc.learned:DiskExtractor", {"max_keypoints": 1024}),
    "xfeat": ("vlocbench.loc.learned:XFeatExtractor", {"max_keypoints": 1024}),
    # XFeat's own budget and the paper's SuperPoint's (hloc's superpoint_aachen: up to 4096):
    # LighterGlue then takes about 25x as long a pair (bench_keypoints.py), for a GPU
    "xfeat-4096": ("vlocbench.loc.learned:XFeatExtractor", {"max_keypoints": 4096}),
}
MATCHERS: dict[str, tuple[str, dict[str, Any]]] = {
    "nn-ratio": ("vlocbench.loc.matchers:MutualNearestNeighbor", {"ratio": 0.8}),
    "nn-hamming": ("vlocbench.loc.matchers:MutualNearestNeighbor", {"ratio": 0.8, "hamming": True}),
    "lightglue-aliked": ("vlocbench.loc.learned:LightGlueMatcher", {"features": "aliked"}),
    "lightglue-disk": ("vlocbench.loc.learned:LightGlueMatcher", {"features": "disk"}),
    "lighterglue-xfeat": ("vlocbench.loc.learned:LightGlueMatcher", {"features": "xfeat"}),
}
# presets whose implementation changed their results since they were introduced: maps and
# episodes are keyed by the revision too, so that results of the old code are not reused
REVISIONS: dict[str, int] = {
    "nn-ratio": 2,  # 2: L2 distances from a matrix product instead of OpenCV's brute force
}
RETRIEVAL: dict[str, tuple[str, dict[str, Any]]] = {
    "vlad": ("vlocbench.loc.retrieval:Vlad", {"clusters": 64}),
    "effnet-gem": ("vlocbench.loc.learned:EfficientNetGem", {}),
    # each image standardized by its own statistics: places found by night too (vlocbench's)
    "effnet-gem-norm": ("vlocbench.loc.learned:EfficientNetGem", {"input_norm": "image"}),
    # NetVLAD over EfficientNet-Lite0, its head trained by vlocbench on generated towns under the
    # paper's conditions (experiments/retrieval_towns.yaml); the weights' digest keys maps and
    # episodes, so new weights never mix with results of the old
    "netvlad-towns": ("vlocbench.loc.netvlad:EfficientNetNetVlad", {"sha256": "99f25c30c52cc23f"}),
}


@dataclass(frozen=True)
class MethodConf:
    """A localization method: local features, their matcher and the retrieval stage."""

    features: str
    matcher: str
    retrieval: str = "vlad"

    def __post_init__(self) -> None:
        for field in ("features", "matcher", "retrieval"):
            require(bool(getattr(self, field)), f"method.{field}", "must not be empty")


METHODS: dict[str, MethodConf] = {
    # the paper's SIFT; VLAD over its own descriptors stands in for NetVLAD / AP-GeM (no PyTorch)
    "sift": MethodConf("sift", "nn-ratio", "vlad"),
    # the stand-in before December 2026: ImageNet's EfficientNet-Lite0 with GeM pooling
    "sift-gem": MethodConf("sift", "nn-ratio", "effnet-gem"),
    # sequential localization: the gallery images nearest to the EKF's pose, no global descriptor
    "sift-prior": MethodConf("sift", "nn-ratio", POSE_PRIOR),
    "orb-teblid": MethodConf("orb-teblid", "nn-hamming", "vlad"),
    # VLAD over a learned method's own descriptors stands in for NetVLAD (a VLAD layer over
    # learned features), as for SIFT: it keeps finding the place at night where
    # EfficientNet-GeM loses it (measured for XFeat, ALIKED and DISK)
    "aliked-lightglue": MethodConf("aliked", "lightglue-aliked", "vlad"),
    "aliked-lightglue-threshold": MethodConf("aliked-threshold", "lightglue-aliked", "vlad"),
    "disk-lightglue": MethodConf("disk", "lightglue-disk", "vlad"),
    "xfeat-lighterglue": MethodConf("xfeat", "lighterglue-xfeat", "vlad"),
    # their retrieval before 2026-12-05 (DISK's before 2026-12-06): ImageNet's EfficientNet-Lite0
    # with GeM pooling
    "aliked-lightglue-gem": MethodConf("aliked", "lightglue-aliked", "effnet-gem"),
    "disk-lightglue-gem": MethodConf("disk", "lightglue-disk", "effnet-gem"),
    "xfeat-lighterglue-gem": MethodConf("xfeat", "lighterglue-xfeat", "effnet-gem"),
    "xfeat-lighterglue-4096": MethodConf("xfeat-4096", "lighterglue-xfeat", "vlad"),
    # with a place descriptor trained for changed conditions, as the paper's NetVLAD and AP-GeM
    # were (vlocbench's: trained on generated towns, loc/netvlad.py)
    "sift-netvlad": MethodConf("sift", "nn-ratio", "netvlad-towns"),
    "xfeat-lighterglue-netvlad": MethodConf("xfeat", "lighterglue-xfeat", "netvlad-towns"),
}


def stage_params(conf: MethodConf) -> dict[str, Any]:
    """What builds each stage of ``conf``: a preset's class and arguments, or a plugin's dotted
    path. Maps and episodes are keyed by it, so that changing a preset's arguments rebuilds them."""
    stages = (("features", FEATURES), ("matcher", MATCHERS), ("retrieval", RETRIEVAL))
    params = {}
    for stage, presets in stages:
        name = getattr(conf, stage)
        revision = [REVISIONS[name]] if name in REVISIONS else []
        params[stage] = [*presets.get(name, (name, {})), *revision]
    return params


def method_conf(name: str) -> MethodConf:
    """The preset method ``name`` (see ``METHODS``)."""
    if name not in METHODS:
        raise UnknownNameError("method", name, METHODS)
    return METHODS[name]


def _load(target: str, kind: str) -> type:
    module, _, attr = target.partition(":") if ":" in target else target.rpartition(".")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ConfigError(kind, f"cannot load {target!r}: {exc}") from None


def _class(kind: str, name: str, presets: dict[str, tuple[str, dict[str, Any]]]) -> type:
    """The class a preset ``name`` or a dotted path names."""
    if name in presets:
        return _load(presets[name][0], kind)
    if "." in name or ":" in name:
        return _load(name, kind)
    raise UnknownNameError(kind, name, [*presets, "or a dotted path package.module:Class"])


def _build(
    kind: str, name: str, presets: dict[str, tuple[str, dict[str, Any]]], protocol: type
) -> Any:
    cls = _class(kind, name, presets)
    obj = cls(name=name, **presets[name][1]) if name in presets else cls()
    if not isinstance(obj, protocol):
        raise ConfigError(kind, f"{name!r} does not implement {protocol.__name__}")
    return obj


def build_features(name: str) -> FeatureExtractor:
    return _build("features", name, FEATURES, FeatureExtractor)


def build_matcher(name: str) -> Matcher:
    return _build("matcher", name, MATCHERS, Matcher)


def matcher_class(name: str) -> type:
    """The class :func:`build_matcher` makes ``name`` of, without making one."""
    return _class("matcher", name, MATCHERS)


def build_retrieval(name: str) -> GlobalDescriptor | None:
    """The global descriptor ``name``; ``None`` for pose-prior retrieval."""
    if name == POSE_PRIOR:
        return None
    return _build("retrieval", name, RETRIEVAL, GlobalDescriptor)
