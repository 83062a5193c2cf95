"""Benchmark metrics (pure numerics): recall, failure rate with a bootstrap interval, failure
fragmentation along the route, tracking error, odometry drift and computation time.

As the paper's code computes them: recall at (0.25 m, 2 deg), (0.5 m, 5 deg) and (5 m, 10 deg)
with thresholds inclusive, on the 3D position error and the full rotation angle between the true
and estimated orientation (a planar x, y, yaw recall is kept beside it); the failure rate
F = (1/N) * sum_i r_i / L_km. Beside recall, the share of answers that are confident and wrong (a
pose returned, but beyond (5 m, 10 deg)): these, not misses, crash a car.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vlocbench.bench.consistency import answer_nees, consistency, ekf_nees
from vlocbench.bench.records import (
    EPISODE_KINDS,
    WRONG_THRESHOLD,
    EpisodeKind,
    EpisodeResult,
    LocalizationRecord,
    localization_columns,
    per_km,
)
from vlocbench.config import require_one_of
from vlocbench.errors import ConfigError
from vlocbench.geometry import wrap_angle
from vlocbench.nav import Drift

# (position m, yaw deg): the paper's three plus a coarse (20 m, 180 deg) "right street" level
RECALL_THRESHOLDS: tuple[tuple[float, float], ...] = (
    (0.25, 2.0),
    (0.5, 5.0),
    (5.0, 10.0),
    (20.0, 180.0),
)
HOTSPOT_BIN_M = 25.0  # failure sites closer than this along the route count as one place
PLACE_RANKS = (1, 5, 10)  # place recognition's Recall@N ...
PLACE_RADII_M = (5.0, 10.0, 25.0)  # ... within these distances (the paper's evaluator's)
# failure-free stretches this short or shorter are left out of the drift figure: the paper's
# analysis (analyze_scenario_logs_paper.py) drops them as double re-initializations
DRIFT_MIN_SEGMENT_M = 0.3


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


def place_recall(
    retrieval_distances_m: Sequence[Sequence[float] | NDArray[np.float64]],
    ranks: Sequence[int] = PLACE_RANKS,
    radii_m: Sequence[float] = PLACE_RADII_M,
) -> tuple[float, ...]:
    """Retrieval alone: per (N, d), N-major, the fraction of queries with one of the first N
    retrieved images within d metres (each query's distances best first). Queries without a
    ranking do not count; NaN for every pair when none has one."""
    ranked = [np.asarray(d, np.float64) for d in retrieval_distances_m if len(d)]
    if not ranked:
        return tuple(float("nan") for _ in ranks for _ in radii_m)
    return tuple(
        float(np.mean([np.min(d[:n]) <= r for d in ranked])) for n in ranks for r in radii_m
    )


def wrong_answers(
    position_error_m: NDArray[np.float64],
    rotation_error_deg: NDArray[np.float64],
    threshold: tuple[float, float] = WRONG_THRESHOLD,
) -> NDArray[np.bool_]:
    """(N,) per query: answered with a pose beyond ``threshold`` (NaN errors: no answer, not
    wrong)."""
    pos = np.asarray(position_error_m, np.float64)
    rot = np.abs(np.asarray(rotation_error_deg, np.float64))
    answered = np.isfinite(pos) & np.isfinite(rot)
    return answered & ((pos > threshold[0]) | (rot > threshold[1]))


def confident_wrong(
    position_error_m: NDArray[np.float64],
    rotation_error_deg: NDArray[np.float64],
    threshold: tuple[float, float] = WRONG_THRESHOLD,
) -> float:
    """Fraction of queries answered with a pose beyond ``threshold`` (NaN errors: no answer, not
    counted as wrong); NaN when there are no queries."""
    if len(position_error_m) == 0:
        return float("nan")
    return float(np.mean(wrong_answers(position_error_m, rotation_error_deg, threshold)))


def drift_segments(result: EpisodeResult) -> tuple[tuple[float, float, float], ...]:
    """The EKF's drift at the end of each failure-free stretch, as the paper measured its
    odometry's 8.5 % and 0.4 deg/m: (distance driven m, position error m, yaw error deg) per
    stretch longer than DRIFT_MIN_SEGMENT_M (empty without a recorded trajectory)."""
    tr = result.trajectory
    if len(tr.time_s) < 2:
        return ()
    ends = [r.time_s for r in result.reinitializations] + [np.inf]
    out, start = [], -np.inf
    for end in ends:
        rows = np.flatnonzero((tr.time_s >= start) & (tr.time_s < end))
        start = end
        if len(rows) < 2:
            continue
        xy = np.stack([tr.true_x_m[rows], tr.true_y_m[rows]], 1)
        driven = float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))
        if driven <= DRIFT_MIN_SEGMENT_M:
            continue
        k = rows[-1]
        pos = float(np.hypot(tr.ekf_x_m[k] - tr.true_x_m[k], tr.ekf_y_m[k] - tr.true_y_m[k]))
        yaw = float(np.degrees(np.abs(wrap_angle(tr.ekf_yaw_rad[k] - tr.true_yaw_rad[k]))))
        out.append((driven, pos, yaw))
    return tuple(out)


@dataclass(frozen=True)
class PooledDrift:
    """Pooled drift of failure-free stretches: mean position error over length (%), mean yaw
    error per metre, and how many stretches."""

    position_percent: float
    yaw_deg_per_m: float
    segments: int


def pooled_drift(segments: Sequence[Sequence[float]]) -> PooledDrift:
    """Mean over stretches ((distance m, position error m, yaw error deg) each, as
    :func:`drift_segments` gives them) of the position error and the yaw error per metre."""
    drifts = [Drift(*map(float, seg)) for seg in segments]
    if not drifts:
        return PooledDrift(float("nan"), float("nan"), 0)
    return PooledDrift(
        float(np.mean([d.position_percent for d in drifts])),
        float(np.mean([d.yaw_deg_per_m for d in drifts])),
        len(drifts),
    )


def nanmean(values: Sequence[float]) -> float:
    """The mean of the finite values; NaN when there are none."""
    finite = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(finite)) if finite else float("nan")


@dataclass(frozen=True)
class Metric:
    """A metric in one declaration: its value per episode, the drives of a cell it is taken from,
    how a cell's repetitions combine, and the column of the report's table of declared metrics
    that shows it. Declared with :func:`declare_metric`, it is computed for every episode stored
    from then on (stored in ``EpisodeMetrics.extra`` under ``name``); episodes stored before have
    none (NaN)."""

    name: str  # the stored key, with its unit as a suffix (``_m``, ``_s``, ``_per_km``)
    episode: Callable[[EpisodeResult], float]
    header: str  # the report's column header
    kinds: tuple[EpisodeKind, ...] = ("failure", "baseline")  # the drives it is taken from
    combine: Callable[[Sequence[float]], float] = nanmean
    digits: int = 1


METRICS: dict[str, Metric] = {}


def declare_metric(metric: Metric) -> Metric:
    """Add ``metric`` to :data:`METRICS` (a name declared twice is an error)."""
    if metric.name in METRICS or metric.name in EPISODE_FIELDS:
        raise ConfigError("metric.name", f"{metric.name!r} is declared already")
    for kind in metric.kinds:
        require_one_of(kind, EPISODE_KINDS, "metric.kinds")
    METRICS[metric.name] = metric
    return metric


@dataclass(frozen=True, kw_only=True)
class EpisodeMetrics:
    """Per-episode figures stored with every result (plain numbers and tuples: JSON-ready)."""

    route_length_m: float
    route_covered_m: float  # up to the farthest point reached (the whole route if completed)
    distance_driven_m: float
    completed: bool  # False: it ran out of time (a failure, "timeout", if the config says so)
    failures: int
    failures_per_km: float  # over the route covered
    failure_sites_s_m: tuple[float, ...]  # arc length along the route where each failure happened
    failure_sites_xy: tuple[tuple[float, float], ...]  # where the car truly was, world m
    failure_causes: tuple[str, ...]  # of every failure, a time-out that counts last
    tracking_error_mean_m: float
    drift_segments: tuple[tuple[float, float, float], ...]  # see drift_segments()
    queries: int
    recall: tuple[float, ...]  # raw localization, 6-DoF errors, at RECALL_THRESHOLDS
    recall_planar: tuple[float, ...]  # the same on planar (x, y, yaw) errors
    confident_wrong: float  # share of queries answered beyond WRONG_THRESHOLD (6-DoF)
    place_recall: tuple[float, ...]  # retrieval alone, Recall@N within d m (PLACE_RANKS x RADII)
    recall_ekf: tuple[float, ...]  # the fused (planar) pose at every simulation step
    lock_losses_per_km: float  # ground_truth drives: EKF resets at the truth per km of route
    ct_mean_s: float  # mean computation time per query (NaN without queries)
    sim_time_s: float
    wall_time_s: float
    extra: dict[str, float] = field(default_factory=dict)  # the declared METRICS, by name

    @classmethod
    def from_stored(cls, stored: Mapping[str, Any]) -> EpisodeMetrics:
        """Read back from the store's JSON: lists become tuples; a field that an earlier version
        did not store is NaN (numbers) or empty (tuples); a stored key that is no field, a metric
        declared since, goes to ``extra``."""
        values: dict[str, Any] = {"extra": dict(stored.get("extra") or {})}
        for f in fields(cls):
            if f.name == "extra":
                continue
            if f.name in stored:
                values[f.name] = _tuples(stored[f.name])
            else:
                values[f.name] = _MISSING[str(f.type).split("[")[0]]
        for name, value in stored.items():
            if name not in EPISODE_FIELDS and name != "extra":
                values["extra"][name] = value
        return cls(**values)


def _tuples(value: Any) -> Any:
    return tuple(_tuples(v) for v in value) if isinstance(value, list | tuple) else value


# what a field an older version did not store reads back as, by its type
_MISSING: dict[str, Any] = {"float": float("nan"), "int": 0, "bool": True, "tuple": ()}
EPISODE_FIELDS = frozenset(f.name for f in fields(EpisodeMetrics))


def episode_metrics(result: EpisodeResult) -> EpisodeMetrics:
    locs = result.localizations
    tr = result.trajectory
    ekf_yaw_err = np.degrees(np.abs(wrap_angle(tr.ekf_yaw_rad - tr.true_yaw_rad)))
    pos3d = np.array([x.position_error_3d_m for x in locs])
    rot = np.array([x.rotation_error_deg for x in locs])
    return EpisodeMetrics(
        route_length_m=result.route_length_m,
        route_covered_m=result.route_covered_m,
        distance_driven_m=result.distance_driven_m,
        completed=result.completed,
        failures=result.failures,
        failures_per_km=result.failures_per_km,
        failure_sites_s_m=tuple(r.resume_s_m for r in result.reinitializations),
        failure_sites_xy=tuple((r.x_m, r.y_m) for r in result.reinitializations),
        failure_causes=result.failure_causes,
        tracking_error_mean_m=result.tracking_error_mean_m,
        drift_segments=drift_segments(result),
        queries=len(locs),
        recall=recall(pos3d, rot),
        recall_planar=recall(
            np.array([x.position_error_m for x in locs]), np.array([x.yaw_error_deg for x in locs])
        ),
        confident_wrong=confident_wrong(pos3d, rot),
        place_recall=place_recall([x.retrieval_distances_m for x in locs]),
        recall_ekf=recall(tr.ekf_position_error_m, ekf_yaw_err) if len(tr.time_s) else (),
        lock_losses_per_km=len(result.lock_losses_s) / (result.route_length_m / 1000.0),
        ct_mean_s=float(np.mean([x.compute_time_s for x in locs])) if locs else float("nan"),
        sim_time_s=result.sim_time_s,
        wall_time_s=result.wall_time_s,
        extra={m.name: float(m.episode(result)) for m in METRICS.values()},
    )


def _mean_stretch_m(result: EpisodeResult) -> float:
    segments = [s.length_m for s in result.segments]
    return float(np.mean(segments)) if segments else result.route_length_m


# declared metrics: what the summary and the report show of them needs nothing more
declare_metric(
    Metric(
        name="mean_segment_m",
        episode=_mean_stretch_m,
        header="distance between failures (m)",
        digits=0,
    )
)
declare_metric(
    Metric(
        name="final_drift_m",
        episode=lambda r: r.final_drift_m,
        header="EKF error at the goal (m)",
        digits=2,
    )
)


def _wrong_answers(result: EpisodeResult) -> list[LocalizationRecord]:
    """The answers beyond WRONG_THRESHOLD (6-DoF), as :func:`confident_wrong` counts them."""
    locs = result.localizations
    pos3d = np.array([x.position_error_3d_m for x in locs], np.float64)
    rot = np.array([x.rotation_error_deg for x in locs], np.float64)
    return [x for x, wrong in zip(locs, wrong_answers(pos3d, rot)) if wrong]


def _wrong_fused_per_km(result: EpisodeResult) -> float:
    """Wrong answers the EKF took (its gate let them through), per km of route covered: what
    moves the filter off the truth, where a wrong answer it rejects costs nothing."""
    fused = sum(1 for x in _wrong_answers(result) if x.fused)
    return per_km(fused, result.route_covered_m) if result.localizations else float("nan")


def _wrong_place_missed_share(result: EpisodeResult, radius_m: float = 10.0) -> float:
    """Of the wrong answers, the share whose retrieval found no image within ``radius_m``: the
    retrieval's misses; the rest went wrong in matching and PnP with the place in hand. NaN with
    no wrong answer or no retrieval."""
    ranked = [x for x in _wrong_answers(result) if x.retrieval_distances_m]
    if not ranked:
        return float("nan")
    return float(np.mean([min(x.retrieval_distances_m) > radius_m for x in ranked]))


declare_metric(
    Metric(
        name="wrong_fused_per_km",
        episode=_wrong_fused_per_km,
        header="wrong answers (beyond 5 m, 10°) the EKF fused, per km",
        kinds=("recall", "failure"),
    )
)
declare_metric(
    Metric(
        name="wrong_place_missed_share",
        episode=_wrong_place_missed_share,
        header="wrong answers whose retrieval had no image within 10 m (share)",
        kinds=("recall", "failure"),
        digits=2,
    )
)


@dataclass(frozen=True)
class FailureRate:
    """F over N repetitions (failures per km) and its bootstrap 95 % interval."""

    mean: float
    low: float
    high: float
    repetitions: int
    per_repetition: tuple[float, ...] = ()  # each repetition's r_i / L_km


def bootstrap_means(
    values: Sequence[float] | NDArray[np.float64], rng: np.random.Generator, resamples: int
) -> NDArray[np.float64]:
    """(resamples,) means of ``values`` drawn again with replacement, from the sorted values: the
    same values in any order give the same means."""
    x = np.sort(np.asarray(values, np.float64))
    return x[rng.integers(0, len(x), (resamples, len(x)))].mean(axis=1)


def percentile_interval(means: NDArray[np.float64]) -> tuple[float, float]:
    """The 95 % percentile interval of bootstrap ``means``."""
    low, high = np.percentile(means, [2.5, 97.5])
    return float(low), float(high)


def failure_rate(
    failures_per_km: Sequence[float], resamples: int = 2000, seed: int = 0
) -> FailureRate:
    """F = mean of the repetitions' r_i / L_km; a percentile bootstrap over repetitions (seeded:
    the same values, in any order, give the same interval). One repetition gives a zero-width
    interval."""
    x = np.asarray(failures_per_km, np.float64)
    if len(x) == 0:
        return FailureRate(float("nan"), float("nan"), float("nan"), 0)
    means = bootstrap_means(x, np.random.default_rng(seed), resamples)
    low, high = percentile_interval(means)
    return FailureRate(float(x.mean()), low, high, len(x), tuple(map(float, x)))


def failure_rate_by_cause(
    causes: Sequence[Sequence[str]], covered_m: Sequence[float]
) -> dict[str, float]:
    """F split by cause over N episodes (each episode's causes and the route it covered): the
    parts add up to F."""
    n = len(causes)
    out: dict[str, float] = {}
    for episode_causes, covered in zip(causes, covered_m):
        for cause in episode_causes:
            out[cause] = out.get(cause, 0.0) + per_km(1, covered) / n
    return dict(sorted(out.items()))


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


def _ekf_consistency(result: EpisodeResult, figure: str) -> float:
    """One figure of :class:`~vlocbench.bench.consistency.Consistency` of the episode's EKF."""
    return float(getattr(consistency(ekf_nees(vars(result.trajectory))), figure))


for _name, _figure, _header, _digits in (
    ("ekf_nees_mean", "mean_nees", "EKF NEES, mean (3: consistent)", 1),
    ("ekf_inside_95_share", "inside_95", "truth inside the EKF's 95 % ellipse (share of steps)", 2),
    (
        "ekf_overconfident_share",
        "above",
        "EKF overconfident (share of steps above the chi-square band; 0.025)",
        2,
    ),
):
    declare_metric(
        Metric(
            name=_name,
            episode=partial(_ekf_consistency, figure=_figure),
            header=_header,
            kinds=("recall", "failure", "baseline"),
            digits=_digits,
        )
    )
# the stages of the map localizer's queries (``QueryResult.seconds``); another localizer's own
# stages are stored with its localizations and take a declaration of their own to be reported
MAP_STAGES = ("features", "retrieval", "matching", "pnp")


def _stage_ms(result: EpisodeResult, stage: str) -> float:
    """Mean time of ``stage`` per query that reported stages (a query that failed before the stage
    spent 0 on it), ms; NaN when no query reported it."""
    timed = [x.stage_s for x in result.localizations if x.stage_s]
    if not any(stage in t for t in timed):
        return float("nan")
    return 1000.0 * float(np.mean([t.get(stage, 0.0) for t in timed]))


for _stage in MAP_STAGES:
    declare_metric(
        Metric(
            name=f"ct_{_stage}_ms",
            episode=partial(_stage_ms, stage=_stage),
            header=f"CT: {_stage} (ms a query)",
            kinds=("recall", "failure"),
            digits=0,
        )
    )
declare_metric(
    Metric(
        name="answer_inside_95_share",
        episode=lambda r: consistency(answer_nees(localization_columns(r.localizations))).inside_95,
        header="truth inside the answer's own 95 % ellipse (share; answers with a covariance)",
        kinds=("recall",),
        digits=2,
    )
)
