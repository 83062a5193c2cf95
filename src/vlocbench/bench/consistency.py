"""Can a localizer's confidence, and the filter's, be trusted? (pure numeric core; no I/O)

- **Filter consistency.** The normalized estimation error squared of the EKF's planar pose at
  every step, NEES = e' P^-1 e over e = (x, y, yaw) error, is chi-square with 3 degrees of freedom
  when the filter is consistent: its mean is 3, and the truth lies inside the filter's 95 %
  ellipse (NEES <= 7.81) at 95 % of the steps. More steps above the upper bound: the filter is
  overconfident (the paper's fixed pose covariance of 0.1 is); more below the lower one: it is
  needlessly cautious. The same for a localizer's answers that carry their own covariance.
- **Answer confidence.** Answers ranked by the method's confidence (PnP inliers, or the inverse
  of its position covariance where every answer has one) against precision, the share within
  (5 m, 10 deg) among those answered: the curve of precision against the share of queries
  answered and its area, as the Map-free benchmark scores confidence (there open loop); and the
  confidence threshold that would have kept precision at 95 %.

Columns are read by name from a :class:`~vlocbench.bench.records.Trajectory` (``vars(t)``), or a
stored episode's trajectory / localization table, so stores written before the covariance was
recorded read as NaN.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vlocbench.bench.records import WRONG_THRESHOLD
from vlocbench.geometry import wrap_angle
from vlocbench.interfaces import Array

# chi-square quantiles for 3 degrees of freedom: 2.5 %, 95 %, 97.5 %
CHI2_3_LOW = 0.2158
CHI2_3_95 = 7.8147
CHI2_3_HIGH = 9.3484
COV_COLUMNS = (
    "ekf_cov_xx_m2",
    "ekf_cov_xy_m2",
    "ekf_cov_xyaw_mrad",
    "ekf_cov_yy_m2",
    "ekf_cov_yyaw_mrad",
    "ekf_cov_yawyaw_rad2",
)
TARGET_PRECISION = 0.95


@dataclass(frozen=True)
class Consistency:
    """NEES over ``steps`` (steps or answers): its mean (3 if consistent), and the shares inside
    the 95 % ellipse (0.95), above the two-sided 95 % band (0.025: overconfident) and below it
    (0.025: too cautious)."""

    mean_nees: float
    inside_95: float
    above: float
    below: float
    steps: int


def nees(errors: Array, covariances: Array) -> Array:
    """(N,) NEES of (N, 3) errors (x m, y m, yaw rad) under (N, 3, 3) covariances; NaN where a
    covariance is missing or singular."""
    out = np.full(len(errors), np.nan)
    ok = np.isfinite(covariances).all(axis=(1, 2)) & np.isfinite(errors).all(axis=1)
    if ok.any():
        cov, err = covariances[ok], errors[ok]
        good = np.linalg.det(cov) > 0
        solved = np.linalg.solve(cov[good], err[good][..., None])[..., 0]
        values = np.full(len(err), np.nan)
        values[good] = np.einsum("ij,ij->i", err[good], solved)
        out[ok] = values
    return out


def consistency(values: Array) -> Consistency:
    """The summary of (N,) NEES values (NaN ignored; all NaN: NaN figures)."""
    x = np.asarray(values, np.float64)
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return Consistency(np.nan, np.nan, np.nan, np.nan, 0)
    return Consistency(
        float(x.mean()),
        float(np.mean(x <= CHI2_3_95)),
        float(np.mean(x > CHI2_3_HIGH)),
        float(np.mean(x < CHI2_3_LOW)),
        len(x),
    )


def upper_to_full(upper: Array) -> Array:
    """(N, 6) upper triangles (xx, xy, xyaw, yy, yyaw, yawyaw) as (N, 3, 3) matrices."""
    full = np.empty((len(upper), 3, 3))
    rows, cols = np.triu_indices(3)
    full[:, rows, cols] = upper
    full[:, cols, rows] = upper
    return full


def ekf_nees(trajectory: Mapping[str, Array]) -> Array:
    """(N,) NEES of the EKF's planar pose at every step of a trajectory; all NaN for one stored
    before the filter's covariance was recorded."""
    t = trajectory
    n = len(t["time_s"])
    if any(c not in t for c in COV_COLUMNS):
        return np.full(n, np.nan)
    errors = np.column_stack(
        [
            np.asarray(t["ekf_x_m"]) - t["true_x_m"],
            np.asarray(t["ekf_y_m"]) - t["true_y_m"],
            wrap_angle(np.asarray(t["ekf_yaw_rad"]) - t["true_yaw_rad"]),
        ]
    )
    upper = np.column_stack([np.asarray(t[c], np.float64) for c in COV_COLUMNS])
    return nees(errors, upper_to_full(upper))


def stored_covariances(column: Sequence[Sequence[float]] | Array, default: Array) -> Array:
    """(N, 3, 3) a localization table's ``covariance`` column (N,), each answer's own row-major
    (x, y, yaw) covariance where it carries one, else ``default`` (3, 3)."""
    return np.array([np.reshape(c, (3, 3)) if len(c) == 9 else default for c in column]).reshape(
        -1, 3, 3
    )


def _answers(locs: Mapping[str, Any]) -> tuple[Array, Array, Array]:
    """The answered queries: (K, 3) errors of the answer, their (K, 3, 3) own covariances (NaN
    where an answer has none), and whether each is right within (5 m, 10 deg) on 6-DoF errors."""
    ok = np.asarray(locs.get("success", []), bool)
    if not ok.any():
        return np.empty((0, 3)), np.empty((0, 3, 3)), np.empty(0, bool)
    col = {k: np.asarray(locs[k], np.float64)[ok] for k in ("x_m", "y_m", "yaw_rad")}
    truth = {k: np.asarray(locs[f"true_{k}"], np.float64)[ok] for k in ("x_m", "y_m", "yaw_rad")}
    errors = np.column_stack(
        [
            col["x_m"] - truth["x_m"],
            col["y_m"] - truth["y_m"],
            wrap_angle(col["yaw_rad"] - truth["yaw_rad"]),
        ]
    )
    covs = [c for c, k in zip(locs.get("covariance", [()] * len(ok)), ok) if k]
    cov = stored_covariances(covs, np.full((3, 3), np.nan))
    right = (np.asarray(locs["position_error_3d_m"], np.float64)[ok] <= WRONG_THRESHOLD[0]) & (
        np.asarray(locs["rotation_error_deg"], np.float64)[ok] <= WRONG_THRESHOLD[1]
    )
    return errors, cov, right


def answer_nees(locs: Mapping[str, Any]) -> Array:
    """(K,) NEES of each answer under its own covariance (NaN where it gave none)."""
    errors, cov, _ = _answers(locs)
    return nees(errors, cov)


@dataclass(frozen=True)
class ConfidenceCurve:
    """Precision against the share of queries answered, answers taken most confident first.

    ``share`` and ``precision``: (K,), K the answers; ``auc``: the area under the curve over the
    share answered (the answered share at most: a method that answers half the queries, all
    right, scores 0.5); ``threshold``: the least confidence at which the answers above it keep
    precision >= 95 % (NaN if none does), and ``share_at_threshold`` what it answers then;
    ``by``: ``inliers`` or ``covariance``."""

    share: Array
    precision: Array
    auc: float
    threshold: float
    share_at_threshold: float
    by: str
    queries: int


def confidence_curve(locs: Mapping[str, Any]) -> ConfidenceCurve:
    """The curve of one drive's (or several drives' pooled) localization records."""
    queries = len(locs.get("success", []))
    _, cov, right = _answers(locs)
    pos_var = cov[:, 0, 0] + cov[:, 1, 1]
    if len(cov) and np.isfinite(pos_var).all() and (pos_var > 0).all():
        confidence, by = 1.0 / pos_var, "covariance"
    else:
        ok = np.asarray(locs.get("success", []), bool)
        confidence, by = (
            np.asarray(locs.get("inliers", np.zeros(queries)), np.float64)[ok],
            "inliers",
        )
    if queries == 0 or len(right) == 0:
        empty = np.empty(0)
        return ConfidenceCurve(
            empty, empty, np.nan if queries == 0 else 0.0, np.nan, 0.0, by, queries
        )
    order = np.argsort(-confidence, kind="stable")
    # answers of equal confidence are answered together: the curve steps at the last of each run
    last = np.r_[np.diff(confidence[order]) != 0, True]
    k = np.arange(1, len(order) + 1)[last]
    share, precision = k / queries, np.cumsum(right[order])[last] / k
    auc = float(np.sum(precision * np.diff(share, prepend=0.0)))
    good = np.flatnonzero(precision >= TARGET_PRECISION)
    threshold, at = np.nan, 0.0
    if len(good):
        threshold, at = float(confidence[order][last][good[-1]]), float(share[good[-1]])
    return ConfidenceCurve(share, precision, auc, threshold, at, by, queries)
