"""Calibration of the light against the paper: T1 recall (6-DoF) of a method against k.

    python benchmarks/bench_illumination.py [--town town10] [--method sift] [--k 0,2,4,6,8,10]
                                            [--queries 60] [--max-gain 512] [--shot-noise 0.02]
                                            [--read-noise 0.02] [--retrieval map|pose-prior]
                                            [--experiment FILE] [--shadows]
                                            [--tone-curve filmic] [--gallery-tone-curve gamma]
                                            [--viewpoint "0,0;2,10;4,22.5"] [--setups FILE]
                                            [--offset "0,0;1,0;-2,0;0,5"]

Renders the gallery camera at ``--queries`` poses spread along the route (half-way between gallery
images), at each illumination level k, localizes each with the method's map (built once under
out/cache, as an experiment would) and prints T1 / T2 / T3 recall beside the paper's Table 5
(SIFT with AP-GeM / NetVLAD), with the median time per query and per stage. The camera's exposure
range and noise (``Exposure``) are the knobs: one setting for every k and both towns, chosen so
that recall falls with k as the paper's does.

``--retrieval pose-prior`` retrieves the map images nearest to the true pose instead of asking the
map's retrieval: the local features alone, to tell their misses from the retrieval's.
``--experiment FILE`` takes ``--town`` and ``--method`` with their settings (gallery, mapping,
localizer) from an experiment, so the maps are that experiment's; a preset method the experiment
does not name runs on its gallery and mapping. ``--shadows``: the sun casts
shadows in the gallery (its own gallery and maps) and in the queries; ``--tone-curve filmic``:
CARLA's camera's tone curve, the gallery's too unless ``--gallery-tone-curve`` says otherwise (the
queries' curve against a map of the other: the curve's effect without a new map). ``--viewpoint`` sweeps the
query camera's (raise m, pitch down deg) levels instead, at the first ``--k`` (the paper's Table 3
has no recall to print beside). ``--setups FILE`` sweeps the conditions of that experiment's setups
(``experiments/paper/weather.yaml``: the paper's fog and rain) with any method's map.
``--offset`` places the query car off the gallery's line: (m to its left, deg of yaw to its left)
pairs, each run at every level, as a car the EKF has let drift sees its street (the gallery's
camera looks to the right: a car to its left stands further from the facades it sees).
``--per-query`` prints each query's position error, PnP inliers and how many of its 5 retrieved
images lie within 10 m.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from vlocbench.bench.experiment import ExperimentPlan, load_experiment, resolve
from vlocbench.bench.localizer import LocalizationQuery
from vlocbench.bench.methods import MethodSpec
from vlocbench.bench.metrics import confident_wrong, place_recall, recall
from vlocbench.bench.paper import paper_results
from vlocbench.bench.preparation import prepare_maps
from vlocbench.bench.towns import route_named, town_named
from vlocbench.bench.visual import VisualLocalizer
from vlocbench.geometry import planar_pose, pose_error
from vlocbench.loc.localizer import RETRIEVAL_SOURCES
from vlocbench.nav import WaypointPath
from vlocbench.sim import Conditions, Exposure, Illumination, Simulator, Viewpoint, Weather
from vlocbench.sim.light import TONE_CURVES

STAGES = ("features", "retrieval", "matching", "pnp")


def method_plan(experiment: Path | None, town: str, method: str) -> ExperimentPlan:
    """The plan of one town and method: ``experiment``'s (its gallery, mapping and method
    settings: the maps it built; a preset it does not name runs on its gallery), or the
    defaults'."""
    if experiment:
        plan = load_experiment(experiment)
        if method not in {m.name for m in plan.spec.methods}:
            plan = resolve(dataclasses.replace(plan.spec, methods=(MethodSpec(method),)))
    else:
        plan = load_experiment(
            {
                "name": "bench_illumination",
                "towns": [town],
                "methods": [method],
                "failure": False,
                "baseline": False,
            }
        )
    return plan.only([town], [method])


def route_queries(route: WaypointPath, count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` query places along ``route``, half-way between gallery images (every 2 m):
    positions (count, 2) in metres and headings (count,) in radians."""
    s = np.linspace(10.0, route.length_m - 10.0, count)
    s = np.round(s / 2.0) * 2.0 + 1.0
    xy = np.stack([np.interp(s, route.s_m, route.xy[:, i]) for i in (0, 1)], 1)
    return xy, np.interp(s, route.s_m, np.unwrap(route.yaw_rad))


def number_pairs(text: str) -> list[tuple[float, float]]:
    """``"a,b;c,d"`` as [(a, b), (c, d)]: the levels of ``--viewpoint`` and ``--offset``."""
    try:
        pairs = [tuple(float(v) for v in p.split(",")) for p in text.split(";")]
    except ValueError:
        pairs = []
    if not pairs or any(len(p) != 2 for p in pairs):
        raise argparse.ArgumentTypeError(f'want number pairs as "a,b;c,d", got {text!r}')
    return [(a, b) for a, b in pairs]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--town", default="town10")
    ap.add_argument("--method", default="sift")
    ap.add_argument("--k", default="0,2,4,6,8,10")
    ap.add_argument("--queries", type=int, default=60)
    defaults = Exposure()
    ap.add_argument("--max-gain", type=float, default=defaults.max_gain)
    ap.add_argument("--shot-noise", type=float, default=defaults.shot_noise)
    ap.add_argument("--read-noise", type=float, default=defaults.read_noise)
    ap.add_argument("--retrieval", default="map", choices=RETRIEVAL_SOURCES)
    ap.add_argument(
        "--experiment",
        type=Path,
        help="take --town and --method with their settings from this file",
    )
    ap.add_argument("--shadows", action="store_true", help="the sun's shadows, gallery too")
    ap.add_argument("--tone-curve", default=defaults.tone_curve, choices=TONE_CURVES)
    ap.add_argument(
        "--gallery-tone-curve", choices=TONE_CURVES, help="the gallery's (default: --tone-curve)"
    )
    ap.add_argument(
        "--viewpoint", type=number_pairs, help='(dz m, pitch down deg) levels, "0,0;2,10"'
    )
    ap.add_argument("--setups", type=Path, help="sweep the conditions of this experiment's setups")
    ap.add_argument(
        "--offset",
        type=number_pairs,
        default=[(0.0, 0.0)],
        help='the query car off the route: (m to its left, yaw deg to its left) pairs, "0,0;1,0"',
    )
    ap.add_argument(
        "--per-query",
        action="store_true",
        help="each query's position error, PnP inliers and retrieved images within 10 m",
    )
    args = ap.parse_args()
    plan = method_plan(args.experiment, args.town, args.method)
    gallery_tone = args.gallery_tone_curve or args.tone_curve
    if args.shadows or gallery_tone != defaults.tone_curve:
        # the gallery too: its own gallery and maps
        g = plan.spec.gallery
        seen = dataclasses.replace(
            g.conditions,
            shadows=args.shadows or g.conditions.shadows,
            exposure=dataclasses.replace(g.conditions.exposure, tone_curve=gallery_tone),
        )
        gallery = dataclasses.replace(g, conditions=seen)
        plan = resolve(dataclasses.replace(plan.spec, gallery=gallery))
    map_dir = prepare_maps(plan, progress=True)[(args.town, args.method)]
    town = town_named(args.town)
    route = route_named(args.town, plan.spec.route_length_m)  # the experiment's cut, if any
    camera = dataclasses.replace(plan.spec.gallery.camera, name="query")
    config = dataclasses.replace(plan.spec.methods[0].localizer, retrieval=args.retrieval)
    localizer = VisualLocalizer(map_dir, (camera,), config, name=args.method)
    exposure = Exposure(
        max_gain=args.max_gain,
        shot_noise=args.shot_noise,
        read_noise=args.read_noise,
        tone_curve=args.tone_curve,
    )
    xy, yaws = route_queries(route, args.queries)
    paper = paper_results().tables["illumination"]
    t1_paper = {m: dict(zip(paper.recall_levels, v)) for m, v in paper.recall_t1[args.town].items()}
    print(
        f"{args.town}, {args.method}, {args.queries} queries, retrieval {args.retrieval}; "
        f"{exposure}; shadows {args.shadows}; gallery tone curve {gallery_tone}"
    )
    # gain: the sensor's; exposure: the share of the metered exposure it reached (1: none short)
    # answered: a pose returned; wrong: answered beyond (5 m, 10 deg); R@5: one of the retrieval's
    # best 5 map images within 10 m of the query (pose-prior retrieval: by construction); ms per
    # query: medians of the localizer's own time and of its stages' (time it on an idle machine)
    print(
        "level | gain | exposure | T1 / T2 / T3 (%) | answered / wrong (%) | R@1 / R@5 10 m (%)"
        " | ms per query (" + " / ".join(STAGES) + ")"
        " | paper AP-GeM / NetVLAD + SIFT T1"
    )
    ks = [float(v) for v in args.k.split(",")]
    levels = [
        (f"k={k:g}", Conditions(illumination=Illumination(k=k), exposure=exposure)) for k in ks
    ]
    if args.viewpoint:
        noon = levels[0][1]
        levels = [
            (f"{dz:g} m, {deg:g} deg", dataclasses.replace(noon, viewpoint=Viewpoint(dz, deg)))
            for dz, deg in args.viewpoint
        ]
    if args.setups:
        levels = [(s.label, s.conditions) for s in load_experiment(args.setups).setups]
    runs = [
        (
            f"{label}, {left:g} m left, {yaw:g} deg" if args.offset != [(0.0, 0.0)] else label,
            c,
            left,
            yaw,
        )
        for left, yaw in args.offset
        for label, c in levels
    ]
    sim = Simulator(town)
    try:
        for label, conditions, left_m, yaw_deg in runs:
            sim.set_conditions(dataclasses.replace(conditions, shadows=args.shadows))
            k = conditions.illumination.k
            pos, rot, ranked, seconds = [], [], [], []
            for (x, y), h in zip(xy, yaws):
                x, y = x - left_m * np.sin(h), y + left_m * np.cos(h)
                h = h + np.radians(yaw_deg)
                sim.teleport(float(x), float(y), float(h))
                truth = planar_pose(float(x), float(y), float(h))
                frames = tuple(sim.render([camera]))
                e = localizer.localize(LocalizationQuery(0.0, frames, truth))
                if e.success and e.world_from_vehicle is not None:
                    p, r = pose_error(truth, e.world_from_vehicle)
                else:
                    p = r = float("nan")
                pos.append(p)
                rot.append(r)
                ranked.append(e.retrieval_distances_m(truth))
                if args.per_query:
                    near = int(np.sum(np.asarray(ranked[-1])[:5] <= 10.0))
                    print(
                        f"  {label} query {len(pos)}: {p:.2f} m, {e.inliers} inliers, {near}/5 near"
                    )
                stages = e.stage_s
                seconds.append([e.compute_time_s, *(stages.get(s, 0.0) for s in STAGES)])
            errors = np.array(pos), np.array(rot)
            rec = recall(*errors)
            answered = float(np.mean(np.isfinite(errors[0])))
            wrong = confident_wrong(*errors)
            r1, r5 = place_recall(ranked, ranks=(1, 5), radii_m=(10.0,))
            ref = " / ".join(
                f"{t1_paper[m].get(int(k), float('nan')):.1f}"
                for m in ("AP-GeM + SIFT", "NetVLAD + SIFT")
            )
            # the paper's recall is of its light alone: beside a setup that changes nothing else
            moved = args.viewpoint or left_m or yaw_deg
            if moved or (conditions.weather, conditions.viewpoint) != (Weather(), Viewpoint()):
                ref = "–"
            gain, share = sim.renderer.gain, sim.renderer.exposure_share
            print(
                f"{label} | {gain:.0f} | {share:.3g} | "
                + " / ".join(f"{100 * v:.1f}" for v in rec[:3])
                + f" | {100 * answered:.1f} / {100 * wrong:.1f} | {100 * r1:.1f} / {100 * r5:.1f}"
                + " | {:.0f} ({:.0f} / {:.0f} / {:.0f} / {:.0f})".format(
                    *1000 * np.median(seconds, axis=0)
                )
                + f" | {ref}",
                flush=True,
            )
    finally:
        sim.close()


if __name__ == "__main__":
    main()
