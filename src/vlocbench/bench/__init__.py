"""The benchmark: composes ``sim``, ``nav`` and ``loc`` into episodes, runs and reports."""

from vlocbench.bench.episode import EpisodeConfig, LatencyConfig, run_episode
from vlocbench.bench.localizer import (
    LocalizationQuery,
    Localizer,
    OracleConfig,
    OracleLocalizer,
    PoseEstimate,
)
from vlocbench.bench.records import (
    EpisodeResult,
    LocalizationRecord,
    Reinitialization,
    Segment,
    Trajectory,
)
from vlocbench.bench.towns import plan_town_route, route_named, town_named

__all__ = [
    "EpisodeConfig",
    "EpisodeResult",
    "LatencyConfig",
    "LocalizationQuery",
    "LocalizationRecord",
    "Localizer",
    "OracleConfig",
    "OracleLocalizer",
    "PoseEstimate",
    "Reinitialization",
    "Segment",
    "Trajectory",
    "plan_town_route",
    "route_named",
    "run_episode",
    "town_named",
]
