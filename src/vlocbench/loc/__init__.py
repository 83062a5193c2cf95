"""Visual localization (hloc's pipeline): galleries, maps and a localizer, stage by stage.

A gallery (images with exact camera poses) -> :func:`build_map` (local features, pairs, matches,
triangulation into a pycolmap reconstruction) -> :class:`MapLocalizer` (retrieval, covisibility
clusters, matching, PnP). Each stage is named by a preset in :mod:`vlocbench.loc.registry`, or by the
dotted path of a user's class. Imports neither ``sim`` nor ``nav``; PyTorch is imported only by the
learned presets (:mod:`vlocbench.loc.learned`), when one is used.
"""

from vlocbench.loc.features import (
    DogSiftExtractor,
    FeatureExtractor,
    Features,
    OrbTeblidExtractor,
    SiftExtractor,
)
from vlocbench.loc.gallery import CameraModel, Gallery, GalleryImage, GalleryWriter
from vlocbench.loc.localizer import LocalizerConfig, MapLocalizer, QueryResult, RigResult
from vlocbench.loc.mapping import MappingConfig, MapReport, build_map, default_map_dir
from vlocbench.loc.matchers import Matcher, MutualNearestNeighbor
from vlocbench.loc.registry import MethodConf, method_conf
from vlocbench.loc.retrieval import GlobalDescriptor, Vlad

__all__ = [
    "CameraModel",
    "DogSiftExtractor",
    "FeatureExtractor",
    "Features",
    "Gallery",
    "GalleryImage",
    "GalleryWriter",
    "GlobalDescriptor",
    "LocalizerConfig",
    "MapLocalizer",
    "MapReport",
    "MappingConfig",
    "Matcher",
    "MethodConf",
    "MutualNearestNeighbor",
    "OrbTeblidExtractor",
    "QueryResult",
    "RigResult",
    "SiftExtractor",
    "Vlad",
    "build_map",
    "default_map_dir",
    "method_conf",
]
