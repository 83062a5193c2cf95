"""Which wrong answers the EKF's gate lets through, and why: a store's failure drives taken apart.

    python benchmarks/bench_gate.py --experiment experiments/paper/illumination.yaml
                                    --town town10 --method xfeat-lighterglue --setup k=8 --setup k=10

Reads the stored failure drives of one town and method at each setup (the present plan's keys), no
rendering. Each answer is right within (5 m, 10 deg), 6-DoF (the confident-wrong threshold). Its
gate is reconstructed from the stored trajectory: the filter's rear-axle pose and covariance at
the last step before the answer arrived (the query's time plus its latency; with
``late_measurements: replay``, before the query's time, where the filter inserts it), the answer moved to
the rear axle as the episode does, and the Mahalanobis distance of the innovation with the
answer's covariance (its own, or the episode's pose covariance); the share of answers where
``distance < gate`` agrees with the stored ``fused`` says how exact that is. Prints, per setup,
for the right answers fused, the wrong ones fused and the wrong ones rejected: how many, and
medians of the innovation (m), of the filter's position sigma (m, sqrt(var x + var y)), of the
distance, and of the PnP inliers (10th and 90th percentiles in brackets); the wrong answers fused
one by one where they are few, with where the car truly was (a place again?); the innovation the gate
admits at the fused answers' median covariances (purely positional ones: gate x sqrt((var x + var
y) / 2 + the answer's var x)); what a floor on the PnP inliers (``--floors``) would have kept
out of the filter; and how many of the drives' failures came within ``--window-s`` of a wrong
answer fused (a failure's time: when the car was nearest to its site). The other failures are
taken apart too: the longest stretch in that window with no answer fused (the filter on odometry
alone), how many answers the gate turned away there, how many queries went unanswered there and
how many of those a localizer's ``min_inliers`` turned away, and the filter's heading error where
that stretch began and a second before the failure (before a collision turns the car), beside its
heading error over every step of the drives. Where they are few, the failures are listed one by
one: where, how long after the last wrong answer fused (and how wrong it was), and that stretch. Where the answers carry their own covariance (``localizer: {covariance:
estimate}``), how consistent it is for the right ones (their NEES against the truth at the
query's time), and the image noise at which it would be: at the median, and for 95 % of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bench_off_line import stored_cut_parser
from vlocbench.bench.consistency import (
    CHI2_3_95,
    COV_COLUMNS,
    answer_nees,
    nees,
    stored_covariances,
    upper_to_full,
)
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.methods import MethodSpec
from vlocbench.bench.metrics import wrong_answers
from vlocbench.bench.store import read_episode_table, read_episodes
from vlocbench.geometry import wrap_angle

MAX_LISTED = 12  # the wrong answers fused are listed one by one up to this many
CHI2_3_MEDIAN = 2.3660  # the median of a chi-square with 3 degrees of freedom


def gate_distances(
    answers: dict[str, NDArray],
    trajectory: dict[str, NDArray],
    rear_m: float,
    pose_cov: NDArray,
    replayed: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Per answer (N,): the Mahalanobis distance of its innovation against the filter before it
    arrived (``replayed``, ``late_measurements: replay``: before its image was taken, where the
    filter inserts it), the innovation's length (m) and the filter's position sigma (m).
    ``trajectory``'s pose and covariance are the vehicle's (the rear axle's moved forward by
    ``rear_m``); ``pose_cov`` (N, 3, 3): the answers' covariances."""
    t = trajectory["time_s"]
    at_s = answers["time_s"] + (0.0 if replayed else answers["latency_s"])
    i = np.clip(np.searchsorted(t, at_s) - 1, 0, len(t) - 1)
    yaw_e = trajectory["ekf_yaw_rad"][i]
    c, s = np.cos(yaw_e), np.sin(yaw_e)
    rear_e = np.stack(
        [trajectory["ekf_x_m"][i] - rear_m * c, trajectory["ekf_y_m"][i] - rear_m * s]
    )
    yaw_a = answers["yaw_rad"]
    rear_a = np.stack(
        [answers["x_m"] - rear_m * np.cos(yaw_a), answers["y_m"] - rear_m * np.sin(yaw_a)]
    )
    r = np.stack([*(rear_a - rear_e), wrap_angle(yaw_a - yaw_e)], axis=1)  # (N, 3)
    cov = upper_to_full(np.column_stack([trajectory[c][i] for c in COV_COLUMNS]))
    # the stored covariance is the vehicle pose's: J P_rear J' with J = d(vehicle)/d(rear)
    jac_inv = np.zeros((len(i), 3, 3))
    jac_inv[:, 0, 0] = jac_inv[:, 1, 1] = jac_inv[:, 2, 2] = 1.0
    jac_inv[:, 0, 2], jac_inv[:, 1, 2] = rear_m * s, -rear_m * c
    p_rear = jac_inv @ cov @ jac_inv.transpose(0, 2, 1)
    d = np.sqrt(nees(r, p_rear + pose_cov))  # r' S^-1 r, as the filter's gate computes it
    sigma = np.sqrt(p_rear[:, 0, 0] + p_rear[:, 1, 1])
    return d, np.hypot(r[:, 0], r[:, 1]), sigma


def main() -> None:
    ap = stored_cut_parser("a label of the sweep, e.g. k=8; again for more", many=True)
    ap.add_argument("--floors", default="50,100", help="inlier floors to try, e.g. 50,100")
    ap.add_argument("--window-s", type=float, default=5.0, help="how long before a failure")
    args = ap.parse_args()
    plan = load_experiment(args.experiment).only([args.town], [args.method], setups=args.setup)
    store = args.store or plan.output_dir
    metrics = {r.key: r.metrics for r in read_episodes(store) if r.metrics is not None}
    for setup in plan.setups:
        drives = [
            t
            for t in plan.tasks()
            if t.kind == "failure" and t.setup.label == setup.label and t.key in metrics
        ]
        if not drives:
            print(f"{setup.label}: no failure drive stored")
            continue
        gate = drives[0].episode.ekf.mahalanobis_gate
        if gate is None:
            raise SystemExit(f"{setup.label}: the filter has no Mahalanobis gate")
        columns: dict[str, list[NDArray]] = {}
        failures: list[FailureContext] = []
        headings: list[NDArray] = []
        for task in drives:
            answers = read_episode_table(store, task.key, "localizations")
            own_nees = answer_nees(answers)  # under the answer's own covariance, NaN if none
            answered = answers["success"].astype(bool)
            unanswered = {k: np.asarray(v)[~answered] for k, v in answers.items()}
            answers = {k: np.asarray(v)[answered] for k, v in answers.items()}
            trajectory = read_episode_table(store, task.key, "trajectory")
            heading_deg = heading_error_deg(trajectory)
            headings.append(heading_deg)
            pose_cov = stored_covariances(answers["covariance"], task.episode.ekf.pose_covariance())
            d, innovation, sigma = gate_distances(
                answers,
                trajectory,
                0.5 * task.episode.vehicle.wheelbase_m,  # the filter's rear axle, as the episode's
                pose_cov,
                replayed=task.episode.ekf.late_measurements == "replay",
            )
            right = ~wrong_answers(answers["position_error_3d_m"], answers["rotation_error_deg"])
            arrived_s = answers["time_s"] + answers["latency_s"]
            fused = answers["fused"].astype(bool)
            wrong_fused = fused & ~right
            for x, y in metrics[task.key].failure_sites_xy:
                # the failure's time: where the car truly was nearest to the failure's site
                at = np.hypot(trajectory["true_x_m"] - x, trajectory["true_y_m"] - y).argmin()
                t_s = float(trajectory["time_s"][at])
                before = np.flatnonzero(wrong_fused & (arrived_s <= t_s))
                last = before[arrived_s[before].argmax()] if len(before) else None
                failures.append(
                    FailureContext(
                        task.repetition,
                        x,
                        y,
                        t_s,
                        None
                        if last is None
                        else WrongAnswer(
                            float(arrived_s[last]),
                            float(answers["position_error_3d_m"][last]),
                            float(answers["rotation_error_deg"][last]),
                            int(answers["inliers"][last]),
                        ),
                        stretch_context(
                            arrived_s[fused],
                            arrived_s[~fused],
                            unanswered,
                            trajectory["time_s"],
                            heading_deg,
                            (t_s - args.window_s, t_s),
                        ),
                    )
                )
            for name, v in (
                ("d", d),
                ("innovation", innovation),
                ("sigma", sigma),
                ("answer_var", pose_cov[:, 0, 0]),
                ("inliers", answers["inliers"].astype(float)),
                ("fused", fused),
                ("right", right),
                ("own_nees", own_nees),
                ("repetition", np.full(len(d), task.repetition)),
                ("x_m", answers["true_x_m"]),
                ("y_m", answers["true_y_m"]),
                ("error_m", answers["position_error_3d_m"]),
                ("error_deg", answers["rotation_error_deg"]),
            ):
                columns.setdefault(name, []).append(v)
        a = {k: np.concatenate(v) for k, v in columns.items()}
        agree = np.mean((a["d"] < gate) == a["fused"])
        print(
            f"{args.town}, {args.method}, {setup.label}: {len(drives)} drives, "
            f"{len(a['d'])} answers; the reconstructed gate agrees with the stored one on "
            f"{100 * agree:.1f} %"
        )
        for name, where in (
            ("right, fused", a["right"] & a["fused"]),
            ("wrong, fused", ~a["right"] & a["fused"]),
            ("wrong, rejected", ~a["right"] & ~a["fused"]),
        ):
            cells = [
                f"{stat(a[k][where])} {k}"
                for k in ("innovation", "sigma", "d", "inliers")
                if where.any()
            ]
            print(f"  {name}: {int(where.sum())} | " + " | ".join(cells))
        listed = np.flatnonzero(~a["right"] & a["fused"])
        if 0 < len(listed) <= MAX_LISTED:
            print(
                "  the wrong answers fused (repetition, the car's true x, y m: error m / deg, "
                "inliers): "
                + "; ".join(
                    f"{a['repetition'][i]:.0f}, ({a['x_m'][i]:.0f}, {a['y_m'][i]:.0f}): "
                    f"{a['error_m'][i]:.2f} / "
                    f"{a['error_deg'][i]:.1f}, {a['inliers'][i]:.0f}"
                    for i in listed
                )
            )
        # a wrong answer fused in the window (start, end] is one less than window_s before
        others = [f for f in failures if f.since_wrong_s >= args.window_s]
        print(
            f"  failures with a wrong answer fused in the {args.window_s:g} s before: "
            f"{len(failures) - len(others)} of {len(failures)}"
        )
        if others:
            stretches = [f.stretch for f in others]
            print(
                f"  the other {len(others)}: the longest stretch with no answer fused "
                f"{stat(np.array([g.length_s for g in stretches]))} s, answers the gate turned "
                f"away there {sum(g.rejected for g in stretches)}, queries unanswered there "
                f"{sum(g.missed for g in stretches)} ({sum(g.floored for g in stretches)} under "
                f"a min_inliers); the filter's heading error where it began "
                f"{stat(np.array([g.heading_from_deg for g in stretches]))} deg, a second before "
                f"the failure {stat(np.array([g.heading_deg for g in stretches]))}"
            )
        if 0 < len(failures) <= MAX_LISTED:
            print("  each failure:")
            for f in failures:
                print(f"    {f}")
        print(f"  the filter's heading error over every step: {stat(np.concatenate(headings))} deg")
        own = a["own_nees"][a["right"]]
        if np.isfinite(own).any():
            print_own_covariance(own[np.isfinite(own)], drives[0].method)
        fused = a["fused"]
        if fused.any():
            var = np.median(a["sigma"][fused]) ** 2 / 2 + np.median(a["answer_var"][fused])
            print(
                f"  admitted at the fused answers' median covariance: {gate * np.sqrt(var):.1f} m"
            )
        for floor in (int(v) for v in args.floors.split(",")):
            under = a["inliers"] < floor
            print(
                f"  a floor of {floor} inliers would have kept out "
                f"{int((under & fused & ~a['right']).sum())} of the wrong answers fused and "
                f"{int((under & fused & a['right']).sum())} of the right ones"
            )


def print_own_covariance(right_nees: NDArray, method: MethodSpec | None) -> None:
    """How consistent the right answers' own covariances are (``right_nees``: their NEES under
    it), and the image noise at which they would be: the covariance scales with its square."""
    px = method.localizer.pixel_noise_px if method is not None else 1.0
    median_px = px * np.sqrt(np.median(right_nees) / CHI2_3_MEDIAN)
    p95_px = px * np.sqrt(np.percentile(right_nees, 95) / CHI2_3_95)
    print(
        f"  the right answers' own covariance ({px:g} px of image noise): NEES {stat(right_nees)} "
        f"({CHI2_3_MEDIAN:.2f} at the median if consistent), the truth inside its 95 % ellipse "
        f"for {100 * np.mean(right_nees <= CHI2_3_95):.1f} %; the median consistent at "
        f"{median_px:.2f} px, 95 % inside at {p95_px:.2f} px"
    )


def in_window(times_s: NDArray, window: tuple[float, float]) -> NDArray[np.bool_]:
    """Which of ``times_s`` lie in (start, end]."""
    return (times_s > window[0]) & (times_s <= window[1])


@dataclass(frozen=True)
class WrongAnswer:
    """A wrong answer the filter fused."""

    arrived_s: float  # the query's time plus its latency
    error_m: float  # 3D position error
    error_deg: float  # rotation angle error
    inliers: int

    def __str__(self) -> str:
        return f"{self.error_m:.1f} m / {self.error_deg:.0f} deg, {self.inliers} inliers"


@dataclass(frozen=True)
class Stretch:
    """The longest stretch of a window before a failure with no answer fused."""

    length_s: float
    rejected: int  # answers the gate turned away in it
    missed: int  # queries unanswered in it
    floored: int  # of them, those a min_inliers turned away
    heading_from_deg: float  # the filter's heading error where it began
    heading_deg: float  # ... and a second before the failure

    def __str__(self) -> str:
        return (
            f"the longest stretch with no answer fused {self.length_s:.1f} s ({self.rejected} "
            f"turned away by the gate, {self.missed} unanswered); heading error "
            f"{self.heading_from_deg:.1f} deg where it began, {self.heading_deg:.1f} a second "
            "before"
        )


@dataclass(frozen=True)
class FailureContext:
    """One failure of a drive and what came before it."""

    repetition: int
    x_m: float
    y_m: float
    time_s: float  # when the car was nearest to the failure's site
    wrong: WrongAnswer | None  # the last wrong answer fused before it
    stretch: Stretch

    @property
    def since_wrong_s(self) -> float:
        """Since the last wrong answer fused arrived (inf: none before the failure)."""
        return np.inf if self.wrong is None else self.time_s - self.wrong.arrived_s

    def __str__(self) -> str:
        last = (
            "no wrong answer fused before"
            if self.wrong is None
            else f"the last wrong answer fused {self.since_wrong_s:.1f} s before ({self.wrong})"
        )
        return (
            f"repetition {self.repetition}, ({self.x_m:.0f}, {self.y_m:.0f}) m at "
            f"{self.time_s:.1f} s: {last}; {self.stretch}"
        )


def stretch_context(
    fused_s: NDArray,
    rejected_s: NDArray,
    unanswered: dict[str, NDArray],
    time_s: NDArray,
    heading_deg: NDArray,
    window: tuple[float, float],
) -> Stretch:
    """Before a failure at ``window``'s end, the longest stretch of the window with no answer
    fused (``fused_s``, ``rejected_s``: when each answer fused, or turned away by the gate,
    arrived; ``unanswered``: the queries with no answer, their reasons say which a
    ``min_inliers`` turned away; ``heading_deg``: the filter's heading error at each step of
    ``time_s``)."""
    edges = np.concatenate([[window[0]], np.sort(fused_s[in_window(fused_s, window)]), [window[1]]])
    longest = int(np.diff(edges).argmax())
    stretch = (edges[longest], edges[longest + 1])
    missed = in_window(unanswered["time_s"] + unanswered["latency_s"], stretch)
    floored = sum("inliers (<" in str(r) for r in unanswered["reason"][missed])
    at = [max(int(np.searchsorted(time_s, s)) - 1, 0) for s in (stretch[0], window[1] - 1.0)]
    return Stretch(
        float(np.diff(stretch)[0]),
        int(in_window(rejected_s, stretch).sum()),
        int(missed.sum()),
        floored,
        float(heading_deg[at[0]]),
        float(heading_deg[at[1]]),
    )


def heading_error_deg(trajectory: dict[str, NDArray]) -> NDArray[np.float64]:
    """(N,) the filter's heading error at every step of a stored trajectory (deg)."""
    return np.degrees(np.abs(wrap_angle(trajectory["ekf_yaw_rad"] - trajectory["true_yaw_rad"])))


def stat(v: NDArray[np.float64]) -> str:
    """Median [10th, 90th percentile]."""
    lo, med, hi = np.percentile(v, [10, 50, 90])
    return f"{med:.2f} [{lo:.2f}, {hi:.2f}]"


if __name__ == "__main__":
    main()
