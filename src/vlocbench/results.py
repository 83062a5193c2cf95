"""A run's results as pandas DataFrames: one call from an output folder to a table of its episodes,
and one per episode for its trajectory and its localizations.

>>> from vlocbench import results
>>> df = results.episodes("out/paper/weather")
>>> failures = df[df.kind != "recall"]           # failure drives and the odometry line
>>> failures.groupby(["town", "method", "weather.fog_visual_range_m"]).failures_per_km.mean()

gives the mean column of the report's failure-rate table (the odometry line is the ``odometry``
method; its drives serve every setup, so its rows carry the setup they were stored under). After
runs of parts of an experiment (``vlocbench run ... --methods sift``), name the experiment file for
all of it: ``results.episodes("out/paper/weather", "experiments/paper/weather.yaml")``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from vlocbench.bench.experiment import setup_label_of
from vlocbench.bench.metrics import PLACE_RADII_M, PLACE_RANKS, RECALL_THRESHOLDS
from vlocbench.bench.runs import Experiment, stored_episodes
from vlocbench.bench.store import EPISODE_COLUMNS, EpisodeRow, read_episode_table

# the columns of each row before its levels and metrics: the store's row but for what is spread
# (the config's levels, the metrics) or bookkeeping
ID_COLUMNS = tuple(
    c for c in EPISODE_COLUMNS if c not in ("config", "metrics", "wall_s", "attempts", "finished")
)
_RECALL = [f"{m:g}m_{d:g}deg" for m, d in RECALL_THRESHOLDS]
# tuple metrics spread over named columns, e.g. recall_0.25m_2deg, place_recall_at5_10m
_SPREAD = {
    "recall": [f"recall_{t}" for t in _RECALL],
    "recall_planar": [f"recall_planar_{t}" for t in _RECALL],
    "recall_ekf": [f"recall_ekf_{t}" for t in _RECALL],
    "place_recall": [f"place_recall_at{n}_{r:g}m" for n in PLACE_RANKS for r in PLACE_RADII_M],
}


def episodes(output_dir: str | Path, plan: Experiment | None = None) -> pd.DataFrame:
    """The episodes of the latest run in ``output_dir``, or every stored episode of ``plan`` (an
    experiment file or its plan: the whole experiment, whichever runs drove its parts), a row
    each: ``ID_COLUMNS`` (given ``plan``, ``setup`` is that plan's, whichever plan stored the
    episode); the setup's swept levels, a column per key (grouped levels spread:
    ``weather.fog_visual_range_m``); every metric of ``EpisodeMetrics`` (recall tuples spread over
    ``recall_0.25m_2deg`` ...), the declared metrics by name, and the episode's ``wall_s``.
    Episodes that ended in an error have NaN metrics and their ``error``."""
    given = plan is not None
    plan, rows = stored_episodes(output_dir, plan)
    levels = {s.label: _levels(s.levels) for s in plan.setups}
    labels = plan.setups_by_key if given else {}
    setups = [setup_label_of(labels, r.key, r.setup) for r in rows]
    records = [_record(r, x, levels.get(x, {})) for r, x in zip(rows, setups)]
    frame = pd.DataFrame.from_records(records)
    if frame.empty:
        return pd.DataFrame(columns=list(ID_COLUMNS))
    first = [c for c in ID_COLUMNS if c in frame] + sorted({k for v in levels.values() for k in v})
    return frame[first + [c for c in frame.columns if c not in first]]


def trajectory(output_dir: str | Path, key: str) -> pd.DataFrame:
    """Episode ``key``'s trajectory, a row per simulation step (0.05 s): time, the true pose, the
    EKF's pose, speeds and odometry (metres, radians, seconds, as stored)."""
    return pd.DataFrame(read_episode_table(output_dir, key, "trajectory"))


def localizations(output_dir: str | Path, key: str) -> pd.DataFrame:
    """Episode ``key``'s localizations, a row per query: its time, success, the estimate, its
    errors (position, 3D position, rotation, yaw) and the method's report (inliers, compute
    time, its time by stage as a dict in ``stage_s``, ...); no rows for an odometry-only
    drive."""
    return pd.DataFrame(read_episode_table(output_dir, key, "localizations"))


def _levels(levels: tuple[tuple[str, Any], ...]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in levels:
        if isinstance(value, dict):
            out |= {f"{key}.{k}": v for k, v in value.items()}
        elif isinstance(value, list | tuple):  # a camera rig: its size
            out[key] = len(value)
        else:
            out[key] = value
    return out


def _record(row: EpisodeRow, setup: str, levels: dict[str, Any]) -> dict[str, Any]:
    record: dict[str, Any] = {c: getattr(row, c) for c in ID_COLUMNS} | {"setup": setup} | levels
    m = row.metrics
    if m is None:
        return record | {"wall_s": row.wall_s}
    for name, value in vars(m).items():
        if name in _SPREAD:
            padded = list(value) + [np.nan] * (len(_SPREAD[name]) - len(value))
            record |= dict(zip(_SPREAD[name], padded, strict=True))
        elif name == "extra":
            record |= value
        else:  # a number, or a list kept whole (failure sites and causes, drift stretches)
            record[name] = value
    return record | {"wall_s": row.wall_s}
