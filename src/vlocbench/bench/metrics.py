"""Benchmark metrics (pure numerics): recall, failure rate with a bootstrap interval, failure
fragmentation along the route, tracking error and computation time.

The recall thresholds and the failure rate F = (1/N) * sum_i r_i / L_km are the paper's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vlocbench.bench.records import EpisodeResult
from vlocbench.geometry import wrap_angle

# (position m, yaw deg): the paper's three plus a coarse (20 m, 180 deg) "right street" level
RECALL_THRESHOLDS: tuple[tuple[float, float], ...] = (
    (0.25, 2.0),
    (0.5, 5.0),
    (5.0, 10.0),
    (20.0, 180.0),
)
HOTSPOT_BIN_M = 25.0  # failure sites closer than this along the route count as one place


def recall(
    position_error_m: NDArray[np.float64],
    yaw_error_deg: NDArray[np.float64],
    thresholds: Sequence[tuple[float, float]] = RECALL_THRESHOLDS,
) -> tuple[float, ...]:
    """Fraction of queries within each (metres, degrees) threshold; NaN errors (failed
    localizations) are misses. Inputs (N,); NaN for every threshold when N = 0."""
    pos = np.nan_to_num(np.asarray(position_error_m, np.float64), nan=np.inf)
    yaw = np.nan_to_num(np.abs(np.asarray(yaw_error_deg, np.float64)), nan=np.inf)
    if len(pos) == 0:
        return tuple(float("nan") for _ in thresholds)
    return tuple(float(np.mean((pos <= m) & (yaw <= d))) for m, d in thresholds)


@dataclass(frozen=True)
class EpisodeMetrics:
    """Per-episode figures stored with every result (plain numbers and lists: JSON-ready)."""

    route_length_m: float
    distance_driven_m: float
    completed: bool
    failures: int
    failures_per_km: float
    failure_sites_s_m: tuple[float, ...]  # arc length along the route where each failure happened
    failure_sites_xy: tuple[tuple[float, float], ...]  # where the car truly was, world m
    failure_causes: tuple[str, ...]
    mean_segment_m: float  # mean length driven between failures (the whole route if none)
    tracking_error_mean_m: float
    final_drift_m: float
    queries: int
    recall: tuple[float, ...]  # raw localization, at RECALL_THRESHOLDS
    recall_ekf: tuple[float, ...]  # the fused pose at every simulation step
    lock_losses_per_km: float  # ground_truth drives: EKF resets at the truth per km of route
    ct_mean_s: float  # mean computation time per query (NaN without queries)
    sim_time_s: float
    wall_time_s: float


def episode_metrics(result: EpisodeResult) -> EpisodeMetrics:
    locs = result.localizations
    tr = result.trajectory
    ekf_yaw_err = np.degrees(np.abs(wrap_angle(tr.ekf_yaw_rad - tr.true_yaw_rad)))
    segments = [s.length_m for s in result.segments]
    return EpisodeMetrics(
        route_length_m=result.route_length_m,
        distance_driven_m=result.distance_driven_m,
        completed=result.completed,
        failures=result.failures,
        failures_per_km=result.failures_per_km,
        failure_sites_s_m=tuple(r.resume_s_m for r in result.reinitializations),
        failure_sites_xy=tuple((r.x_m, r.y_m) for r in result.reinitializations),
        failure_causes=tuple(r.cause for r in result.reinitializations),
        mean_segment_m=float(np.mean(segments)) if segments else result.route_length_m,
        tracking_error_mean_m=result.tracking_error_mean_m,
        final_drift_m=result.final_drift_m,
        queries=len(locs),
        recall=recall(
            np.array([x.position_error_m for x in locs]), np.array([x.yaw_error_deg for x in locs])
        ),
        recall_ekf=recall(tr.ekf_position_error_m, ekf_yaw_err) if len(tr.time_s) else (),
        lock_losses_per_km=len(result.lock_losses_s) / (result.route_length_m / 1000.0),
        ct_mean_s=float(np.mean([x.compute_time_s for x in locs])) if locs else float("nan"),
        sim_time_s=result.sim_time_s,
        wall_time_s=result.wall_time_s,
    )


@dataclass(frozen=True)
class FailureRate:
    """F over N repetitions (failures per km) and its bootstrap 95 % interval."""

    mean: float
    low: float
    high: float
    repetitions: int


def failure_rate(
    failures_per_km: Sequence[float], resamples: int = 2000, seed: int = 0
) -> FailureRate:
    """F = mean of the repetitions' r_i / L_km; a percentile bootstrap over repetitions (seeded:
    the same inputs give the same interval). One repetition gives a zero-width interval."""
    x = np.asarray(failures_per_km, np.float64)
    if len(x) == 0:
        return FailureRate(float("nan"), float("nan"), float("nan"), 0)
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, len(x), (resamples, len(x)))].mean(axis=1)
    low, high = np.percentile(means, [2.5, 97.5])
    return FailureRate(float(x.mean()), float(low), float(high), len(x))


@dataclass(frozen=True)
class Fragmentation:
    """How failures spread along the route: ``places`` distinct HOTSPOT_BIN_M stretches hold
    failures; ``top_share`` of them fall in the single worst stretch (1.0: one hotspot)."""

    failures: int
    places: int
    top_share: float
    worst_s_m: float  # start of the worst stretch along the route


def fragmentation(sites_s_m: Sequence[float], bin_m: float = HOTSPOT_BIN_M) -> Fragmentation:
    s = np.asarray(sites_s_m, np.float64)
    if len(s) == 0:
        return Fragmentation(0, 0, float("nan"), float("nan"))
    bins, counts = np.unique(np.floor(s / bin_m).astype(np.int64), return_counts=True)
    worst = int(np.argmax(counts))
    return Fragmentation(
        len(s), len(bins), float(counts[worst] / len(s)), float(bins[worst] * bin_m)
    )
