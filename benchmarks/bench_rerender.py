"""Where a stored wrong answer comes from: each one rendered again at its true pose and localized
with the map, under the stored conditions and under changed ones.

    python benchmarks/bench_rerender.py --experiment experiments/paper/illumination.yaml
        --town town01 --method xfeat-lighterglue --setup k=9 --setup k=10 --near 395,-1
        --set street_lights.mode=off --set street_lights.windows=false --set illumination.k=0

Reads the stored failure drives (``--kind recall``: the ground-truth drive) of one town and method
at each setup (the present plan's keys), and takes the answers that were wrong (beyond (5 m, 10
deg), 6-DoF, the confident-wrong threshold), those within ``--radius-m`` of ``--near`` (x, y m, the
car's true position) or, without it, the ones the filter fused (the ground-truth drive: every
wrong one), at most ``--max``. Each is rendered again as the drive saw it (the
episode's scene, light, weather and sensor noise; no traffic) and localized with the method's
map and localizer: the first column says whether the stored answer comes back (it should, to
the inlier: rendering and localization are deterministic; errors are the vehicle's pose's, as
the episode scores its answers). Each ``--set`` is one variant of the
conditions, one or more ``field=value`` assignments joined by ``;`` (a field of the stored
``conditions``, dotted; the value a number, true, false, null or text): the same query rendered under it and localized
again (``--images``: each rendered query written as answerNN_again.png, answerNN_setK.png).
Prints a line per answer, error (m / deg) and PnP inliers in each column, and per column
how many of the answers come out right.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from bench_off_line import stored_cut_parser
from vlocbench.bench.experiment import EpisodeTask, load_experiment, set_dotted
from vlocbench.bench.metrics import wrong_answers
from vlocbench.bench.replay import QueryRenderer
from vlocbench.bench.store import read_episode_table, read_episodes
from vlocbench.bench.visual import camera_model
from vlocbench.config import from_dict
from vlocbench.errors import ConfigError
from vlocbench.geometry import invert_pose, pose_error
from vlocbench.loc.localizer import MapLocalizer
from vlocbench.sim.conditions import Conditions

Case = tuple[EpisodeTask, dict[str, Any], dict[str, NDArray], int]  # drive, config, answers, which


def parse_variant(text: str) -> dict[str, Any]:
    """``"street_lights.mode=off; illumination.k=0"`` as {dotted field: value}."""
    out = {}
    for item in filter(None, (s.strip() for s in text.split(";"))):
        field, sep, value = item.partition("=")
        if not sep or not field.strip():
            raise ConfigError("--set", f"{item!r} is not field=value")
        out[field.strip()] = scalar(value.strip())
    return out


def scalar(text: str) -> Any:
    """A number, true, false or null; any other text as it is (YAML 1.1 would read ``off`` as
    false)."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {"true": True, "false": False, "null": None}.get(text.lower(), text)


def with_conditions(config: dict[str, Any], changes: dict[str, Any]) -> dict[str, Any]:
    """A copy of a stored episode ``config`` with its conditions' dotted fields changed."""
    out = copy.deepcopy(config)
    for field, value in changes.items():  # Conditions checks the names when it is built
        set_dotted(out["setup"]["conditions"], field, value, f"--set {field}")
    return out


def chosen_answers(
    answers: dict[str, NDArray],
    near: tuple[float, float] | None,
    radius_m: float,
    fused_only: bool,
) -> NDArray[np.int64]:
    """The wrong answers near ``near`` (the car's true x, y), or the wrong ones (``fused_only``:
    those the filter fused)."""
    wrong = answers["success"].astype(bool) & wrong_answers(
        answers["position_error_3d_m"], answers["rotation_error_deg"]
    )
    if near is None:
        return np.flatnonzero(wrong & answers["fused"].astype(bool) if fused_only else wrong)
    d = np.hypot(answers["true_x_m"] - near[0], answers["true_y_m"] - near[1])
    return np.flatnonzero(wrong & (d <= radius_m))


def main() -> None:
    ap = stored_cut_parser("a label of the sweep, e.g. k=8; again for more", many=True)
    ap.add_argument("--near", help="x,y (m): the wrong answers with the car within --radius-m")
    ap.add_argument("--radius-m", type=float, default=6.0)
    ap.add_argument("--kind", choices=("failure", "recall"), default="failure")
    ap.add_argument("--max", type=int, default=20, help="at most this many answers")
    ap.add_argument("--images", type=Path, help="write each rendered query here (PNG)")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        help="a variant of the conditions: field=value[; field=value], e.g. street_lights.mode=off",
    )
    args = ap.parse_args()
    try:
        near = tuple(float(v) for v in args.near.split(",")) if args.near else None
    except ValueError:
        near = ()
    if near is not None and len(near) != 2:
        raise SystemExit(f"--near takes x,y in metres, got {args.near!r}")
    variants = {text: parse_variant(text) for text in args.set}
    plan = load_experiment(args.experiment).only([args.town], [args.method], setups=args.setup)
    store = args.store or plan.output_dir
    stored = {r.key: r for r in read_episodes(store) if r.metrics is not None}
    cases: list[Case] = []
    for task in plan.tasks():
        if task.kind == args.kind and task.key in stored:
            answers = read_episode_table(store, task.key, "localizations")
            for i in chosen_answers(answers, near, args.radius_m, args.kind == "failure"):
                cases.append((task, stored[task.key].config, answers, int(i)))
    if not cases:
        raise SystemExit("no wrong answer stored there")
    cases = cases[: args.max]
    for text, changes in variants.items():  # every variant checked before any is rendered
        try:
            from_dict(Conditions, with_conditions(cases[0][1], changes)["setup"]["conditions"])
        except ConfigError as exc:
            raise SystemExit(f"--set {text!r}: {exc}") from None
    method = cases[0][0].method
    assert method is not None  # a method's drive
    localizer = MapLocalizer(cases[0][1]["map_dir"], method.localizer)
    columns = {
        name: localize_again(cases, changes, localizer, args.images, f"set{k}" if k else "again")
        for k, (name, changes) in enumerate([("again", {}), *variants.items()])
    }
    print(
        f"{args.town}, {args.method}: {len(cases)} wrong answers; each column: error m / deg, "
        f"inliers; {', '.join(f'[{k + 1}] {v}' for k, v in enumerate(variants))}"
    )
    for n, (task, _, answers, i) in enumerate(cases):
        stored_cell = (
            f"{answers['position_error_3d_m'][i]:.2f} / {answers['rotation_error_deg'][i]:.1f}, "
            f"{answers['inliers'][i]:.0f}"
        )
        cells = [cell(*columns[name][n]) for name in columns]
        print(
            f"  {task.setup.label} rep {task.repetition}, t {answers['time_s'][i]:.1f} s, "
            f"({answers['true_x_m'][i]:.0f}, {answers['true_y_m'][i]:.0f}): stored {stored_cell} "
            f"| " + " | ".join(cells)
        )
    for k, name in enumerate(columns):
        errors = np.array([(e, d) for e, d, _ in columns[name]])
        right = np.isfinite(errors[:, 0]) & ~wrong_answers(errors[:, 0], errors[:, 1])
        label = "rendered again" if k == 0 else f"[{k}] {name}"
        print(f"  {label}: {int(right.sum())} of {len(cases)} right")


def localize_again(
    cases: list[Case],
    changes: dict[str, Any],
    localizer: MapLocalizer,
    images: Path | None,
    tag: str,
) -> list[tuple[float, float, int]]:
    """Each case's query rendered under its conditions with ``changes`` and localized: the
    vehicle's position (m) and rotation (deg) error, as the episode scores its answers, and the
    inliers (inf, inf, 0: no answer). ``images``: where to write each query as answerNN_tag.png."""
    out: list[tuple[float, float, int]] = []
    renderers: dict[str, QueryRenderer] = {}  # one scene per town, conditions and camera
    for _, config, answers, i in cases:
        config = with_conditions(config, changes)
        same = json.dumps([config["town"], config["setup"]], sort_keys=True)
        if same not in renderers:
            renderers[same] = QueryRenderer(config)
        renderer = renderers[same]
        frame = renderer.frame(
            answers["true_x_m"][i],
            answers["true_y_m"][i],
            answers["true_yaw_rad"][i],
            answers["time_s"][i],
        )
        if images is not None:
            images.mkdir(parents=True, exist_ok=True)
            bgr = cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR)
            cv2.imwrite(str(images / f"answer{len(out):02d}_{tag}.png"), bgr)
        result = localizer.localize(frame.image, camera_model(renderer.camera))
        if result.world_from_cam is None:
            out.append((np.inf, np.inf, 0))
            continue
        cam_from_vehicle = invert_pose(renderer.camera.extrinsics.vehicle_from_cam())
        error = pose_error(
            frame.world_from_cam @ cam_from_vehicle, result.world_from_cam @ cam_from_vehicle
        )
        out.append((*error, result.num_inliers))
    for renderer in renderers.values():
        renderer.close()
    return out


def cell(error_m: float, error_deg: float, inliers: int) -> str:
    return (
        "no answer" if not np.isfinite(error_m) else f"{error_m:.2f} / {error_deg:.1f}, {inliers}"
    )


if __name__ == "__main__":
    main()
