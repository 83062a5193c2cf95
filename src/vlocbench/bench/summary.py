"""Aggregating a run's episodes into the figures of the paper's tables (pure; no I/O).

One :class:`Cell` per (town, method, setup): the failure rate over the repetitions with its
bootstrap interval, the recall of the ground-truth drive, computation time, fragmentation of the
failure sites and tracking error. The odometry-only baseline is the method ``odometry``; setups that
share its key (the same traffic) share its cell.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from vlocbench.bench.experiment import (
    BASELINE_CONDITIONS,
    ExperimentPlan,
    ExperimentSpec,
    Setup,
    baseline_drive,
)
from vlocbench.bench.metrics import (
    METRICS,
    FailureRate,
    Fragmentation,
    PooledDrift,
    failure_rate,
    failure_rate_by_cause,
    fragmentation,
    nanmean,
    pooled_drift,
)
from vlocbench.bench.store import EpisodeRow
from vlocbench.config import to_dict

BASELINE = "odometry"


@dataclass(frozen=True, kw_only=True)
class Cell:
    town: str
    method: str
    setup: str
    failure: FailureRate | None  # None: no failure episodes
    failure_by_cause: dict[str, float]  # F split by cause (collision, timeout, ...)
    timeouts: int  # failure episodes that ran out of time
    recall: tuple[float, ...] | None  # raw localization, 6-DoF errors, ground-truth drive
    recall_planar: tuple[float, ...] | None  # the same on planar (x, y, yaw) errors
    confident_wrong: float  # share of the drive's queries answered beyond (5 m, 10 deg)
    place_recall: tuple[float, ...] | None  # retrieval alone, Recall@N within d m (metrics.PLACE_*)
    recall_ekf: tuple[float, ...] | None
    lock_losses_per_km: float  # of the EKF in the ground-truth drive (NaN: none, or not recorded)
    ct_s: float  # mean computation time per query (NaN: none)
    fragmentation: Fragmentation | None
    tracking_error_m: float
    extra: dict[str, float]  # the declared metrics (metrics.METRICS), each combined as declared
    drift: PooledDrift  # the EKF's at the end of failure-free stretches of the failure episodes
    sites_xy: tuple[tuple[float, float], ...]  # failure sites of all repetitions
    errors: int  # episodes that ended in an error (not counted above)
    keys: frozenset[str]  # the episodes behind this cell (a baseline's serve several setups)


@dataclass(frozen=True, kw_only=True)
class Summary:
    plan: ExperimentPlan
    # the experiment's towns (as given: names or YAML paths) and methods (then BASELINE when the
    # plan has it) with an episode stored; all of them when none has
    towns: tuple[str, ...]
    town_names: dict[str, str]  # as given -> the town's name
    methods: tuple[str, ...]
    setups: tuple[Setup, ...]
    axis: tuple[str, ...]  # the swept keys
    cells: dict[tuple[str, str, str], Cell]  # (town, method, setup label)
    errors: tuple[EpisodeRow, ...]
    episodes: int  # the episodes summarized, with errors or not
    planned: int  # the episodes the plan consists of (more than the above: a run not finished)
    # episodes by the id of the platform they ran on (None: not recorded, stored before it was)
    platforms: dict[str | None, int]

    @property
    def spec(self) -> ExperimentSpec:
        return self.plan.spec

    @property
    def towns_not_stored(self) -> tuple[str, ...]:
        """The names of the plan's towns with no episode stored (left out of the tables)."""
        return tuple(self.town_names[t] for t in self.spec.towns if t not in self.towns)

    @property
    def methods_not_stored(self) -> tuple[str, ...]:
        """The plan's methods (BASELINE among them) with no episode stored in any town."""
        return tuple(m for m in _planned_methods(self.spec) if m not in self.methods)

    def cell(self, town: str, method: str, setup: str) -> Cell | None:
        return self.cells.get((town, method, setup))

    def failure_mean(self, town: str, method: str, setup: str) -> float:
        """A cell's F (failures/km, mean over its repetitions); NaN without failure episodes."""
        c = self.cell(town, method, setup)
        return c.failure.mean if c is not None and c.failure is not None else float("nan")


def _planned_methods(spec: ExperimentSpec) -> tuple[str, ...]:
    return tuple(m.name for m in spec.methods) + ((BASELINE,) if spec.baseline else ())


def _stored_cells(
    plan: ExperimentPlan, drives: Sequence[tuple[str, dict[str, Any]]], row: EpisodeRow
) -> list[tuple[str, str, str]]:
    """The cells of a row that no episode of ``plan`` has: the setup it was stored for; a
    baseline's every setup whose drive (``drives``: label, :func:`_drive` of each setup) is its."""
    town = row.config["town"]
    if row.method != BASELINE:
        return [(town, row.method, row.setup)]
    conditions = row.config["setup"]["conditions"]
    drive = _drive(
        {name: conditions.get(name) for name in BASELINE_CONDITIONS}, row.config["episode"]
    )
    return [(town, BASELINE, label) for label, d in drives if d == drive]


def _drive(world: dict[str, Any], episode: dict[str, Any]) -> dict[str, Any]:
    """What an odometry-only drive depends on, as stored: its part of the conditions and the
    episode settings (the seed and mode are set per repetition)."""
    return {
        "world": world,
        "episode": {k: v for k, v in episode.items() if k not in ("seed", "mode")},
    }


def _cell(key: tuple[str, str, str], group: list[EpisodeRow], errors: int) -> Cell:
    """The figures of one (town, method, setup) from its episodes' stored metrics, read in
    repetition order (the store gives them by key)."""
    group = sorted(group, key=lambda r: (r.repetition, r.key))
    fail = [r.metrics for r in group if r.kind in ("failure", "baseline") and r.metrics]
    rec = [r.metrics for r in group if r.kind == "recall" and r.metrics]
    sites = [s for m in fail for s in m.failure_sites_s_m]
    town, method, setup = key
    return Cell(
        town=town,
        method=method,
        setup=setup,
        failure=failure_rate([m.failures_per_km for m in fail]) if fail else None,
        failure_by_cause=failure_rate_by_cause(
            [m.failure_causes for m in fail], [m.route_covered_m for m in fail]
        ),
        timeouts=sum(not m.completed for m in fail),
        recall=rec[0].recall if rec else None,
        recall_planar=rec[0].recall_planar if rec else None,
        confident_wrong=rec[0].confident_wrong if rec else float("nan"),
        # episodes stored before place recognition was scored have none
        place_recall=rec[0].place_recall or None if rec else None,
        recall_ekf=rec[0].recall_ekf if rec else None,
        lock_losses_per_km=rec[0].lock_losses_per_km if rec else float("nan"),
        ct_s=nanmean([r.metrics.ct_mean_s for r in group if r.metrics]),
        fragmentation=fragmentation(sites) if fail else None,
        tracking_error_m=nanmean([m.tracking_error_mean_m for m in fail]),
        extra={
            name: metric.combine(
                [
                    r.metrics.extra.get(name, float("nan"))
                    for r in group
                    if r.kind in metric.kinds and r.metrics
                ]
            )
            for name, metric in METRICS.items()
        },
        drift=pooled_drift([seg for m in fail for seg in m.drift_segments]),
        sites_xy=tuple((float(x), float(y)) for m in fail for x, y in m.failure_sites_xy),
        errors=errors,
        keys=frozenset(r.key for r in group),
    )


def summarize(plan: ExperimentPlan, rows: Sequence[EpisodeRow]) -> Summary:
    """Aggregate ``rows`` (one run's episodes, or a store's) by town, method and setup of
    ``plan``. Rows are found by the keys of the plan's episodes, so an episode another experiment
    stored first counts under this plan's setup; a row of none of them (stored by an earlier
    EPISODE_VERSION, as when an old run's report is made again) counts where it was stored."""
    cells_of = plan.cells_by_key
    drives = [
        (s.label, _drive(to_dict(baseline_drive(s.conditions)), to_dict(s.episode)))
        for s in plan.setups
    ]
    by: dict[tuple[str, str, str], list[EpisodeRow]] = defaultdict(list)
    errors_by: dict[tuple[str, str, str], int] = defaultdict(int)
    for r in rows:
        for cell in cells_of.get(r.key) or _stored_cells(plan, drives, r):
            if r.status == "ok" and r.metrics is not None:
                by[cell].append(r)
            elif r.status != "ok":
                errors_by[cell] += 1
    cells = {key: _cell(key, group, errors_by.get(key, 0)) for key, group in by.items()}
    spec = plan.spec
    planned_methods = _planned_methods(spec)
    town_names = {t: t for t in spec.towns} | {r.config["town"]: r.town for r in rows}
    # a run in parts (--towns, --methods) reports what it has; a store with nothing, the plan
    stored = {*by, *errors_by}
    towns = tuple(t for t in spec.towns if any(c[0] == t for c in stored)) or spec.towns
    methods = tuple(m for m in planned_methods if any(c[1] == m for c in stored)) or planned_methods
    return Summary(
        plan=plan,
        towns=towns,
        town_names=town_names,
        methods=methods,
        setups=plan.setups,
        axis=plan.axis,
        cells=cells,
        errors=tuple(r for r in rows if r.status != "ok"),
        episodes=len(rows),
        planned=len(plan.tasks()),
        platforms=dict(Counter(r.platform for r in rows)),
    )
