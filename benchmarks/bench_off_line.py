"""Where a method's failure drives lose the answers its ground-truth drive gets: at the places the
ground-truth drive misses too, or with the car off the gallery's line.

    python benchmarks/bench_off_line.py --experiment experiments/paper/illumination.yaml
                                        --town town10 --method xfeat-lighterglue --setup k=10

Reads the stored episodes of one town, method and setup of an experiment (the present plan's keys:
nothing stored under other maps or settings), no rendering. Each failure drive's answers are
split by the place (whether the ground-truth drive's answer nearest to it along the route was
right) and by where the car stood against the gallery's nearest image: its offset across the
gallery car's heading (m) and its yaw against it (deg); at the hard places, on that line or off
it. An answer is right within (5 m, 10 deg), 6-DoF, the confident-wrong threshold. Prints, per
drive, the share right in each class and how many answers fell in it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vlocbench.bench.experiment import ExperimentPlan, load_experiment
from vlocbench.bench.metrics import WRONG_THRESHOLD
from vlocbench.bench.preparation import prepare_gallery
from vlocbench.bench.store import read_episode_table, read_episodes
from vlocbench.geometry import invert_pose, wrap_angle

# the car's pose against the gallery's line: (name, offset across it m [lo, hi), |yaw| deg [lo, hi))
CLASSES = (
    ("on the line (< 0.5 m, < 20 deg)", (0.0, 0.5), (0.0, 20.0)),
    ("0.5-2 m off, < 20 deg", (0.5, 2.0), (0.0, 20.0)),
    ("< 2 m off, >= 20 deg", (0.0, 2.0), (20.0, 181.0)),
    (">= 2 m off", (2.0, np.inf), (0.0, 181.0)),
)


def gallery_car_poses(plan: ExperimentPlan, town: str) -> NDArray[np.float64]:
    """(N, 3) x, y (m) and yaw (rad) of the car that took each of ``town``'s gallery images."""
    vehicle_from_cam = plan.spec.gallery.camera.extrinsics.vehicle_from_cam()
    cam_from_vehicle = invert_pose(vehicle_from_cam)
    poses = [im.world_from_cam @ cam_from_vehicle for im in prepare_gallery(plan, town).images]
    return np.array([[p[0, 3], p[1, 3], np.arctan2(p[1, 0], p[0, 0])] for p in poses])


def against_line(
    table: dict[str, NDArray], cars: NDArray[np.float64]
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Per answer: the nearest gallery image's index, the car's offset across that image's car
    heading (m, absolute), its yaw against it (deg, absolute), and whether it was right."""
    x, y, yaw = table["true_x_m"], table["true_y_m"], table["true_yaw_rad"]
    nearest = np.hypot(x[:, None] - cars[None, :, 0], y[:, None] - cars[None, :, 1]).argmin(1)
    gx, gy, gyaw = cars[nearest].T
    across = np.abs(-np.sin(gyaw) * (x - gx) + np.cos(gyaw) * (y - gy))
    dyaw = np.degrees(np.abs(wrap_angle(yaw - gyaw)))
    pos = np.nan_to_num(table["position_error_3d_m"].astype(float), nan=np.inf)
    rot = np.nan_to_num(table["rotation_error_deg"].astype(float), nan=np.inf)
    right = (pos <= WRONG_THRESHOLD[0]) & (rot <= WRONG_THRESHOLD[1])
    return nearest, across, dyaw, right


def stored_cut_parser(setup_help: str, many: bool = False) -> argparse.ArgumentParser:
    """Arguments naming a cut of an experiment's stored episodes: one town, one method, a setup
    (``many``: one or more, ``--setup`` repeated as ``vlocbench run`` takes it)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--experiment", type=Path, required=True)
    ap.add_argument("--town", required=True)
    ap.add_argument("--method", required=True)
    ap.add_argument("--setup", required=True, help=setup_help, action="append" if many else "store")
    ap.add_argument("--store", type=Path, help="default: the experiment's output")
    return ap


def main() -> None:
    args = stored_cut_parser("a label of the sweep, e.g. k=10").parse_args()
    plan = load_experiment(args.experiment).only([args.town], [args.method], setups=[args.setup])
    if len(plan.setups) != 1:  # a level of one key of several swept
        raise SystemExit(
            f"{args.setup!r} names {len(plan.setups)} setups; name one of: "
            + "; ".join(x.label for x in plan.setups)
        )
    store = args.store or plan.output_dir
    stored = {r.key for r in read_episodes(store) if r.metrics is not None}
    tasks = [t for t in plan.tasks() if t.key in stored and t.method is not None]
    truth = [t for t in tasks if t.kind == "recall"]
    drives = sorted((t for t in tasks if t.kind == "failure"), key=lambda t: t.repetition)
    if not truth or not drives:
        raise SystemExit(f"{store} holds no ground-truth drive or no failure drive of that cut")
    cars = gallery_car_poses(plan, args.town)
    j, _, _, right = against_line(read_episode_table(store, truth[0].key, "localizations"), cars)
    # each gallery image's place: right if the ground-truth answer nearest to it was
    answered = np.unique(j)
    right_at = np.array([right[j == k].mean() >= 0.5 for k in answered])
    place_right = right_at[np.abs(np.arange(len(cars))[:, None] - answered).argmin(1)]
    print(
        f"{args.town}, {args.method}, {args.setup}: ground-truth drive {100 * right.mean():.1f} % "
        f"right ({len(right)} answers); a place is hard where its answer was wrong "
        f"({100 * (1 - place_right).mean():.0f} % of the gallery's places)"
    )
    # at the hard places, whether the car was on the line: off it, an answer is counted at the
    # place nearest to an excursion, which begins where the car failed
    print(
        f"drive | right % (answers) | at hard places: {CLASSES[0][0]} | off it | at easy places: "
        + " | ".join(c[0] for c in CLASSES)
    )
    for t in drives:
        nearest, across, dyaw, ok = against_line(
            read_episode_table(store, t.key, "localizations"), cars
        )
        easy = place_right[nearest]
        within = [
            (across >= a0) & (across < a1) & (dyaw >= y0) & (dyaw < y1)
            for _, (a0, a1), (y0, y1) in CLASSES
        ]
        cells = [
            f"{100 * ok.mean():.1f} ({len(ok)})",
            share(ok, ~easy & within[0]),
            share(ok, ~easy & ~within[0]),
            *(share(ok, easy & w) for w in within),
        ]
        print(f"rep {t.repetition} | " + " | ".join(cells))


def share(right: NDArray[np.bool_], where: NDArray[np.bool_]) -> str:
    """The share right among ``where``'s answers, and how many they were."""
    n = int(where.sum())
    return f"{100 * right[where].mean():.1f} ({n})" if n else "- (0)"


if __name__ == "__main__":
    main()
