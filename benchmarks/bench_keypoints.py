"""The keypoint budget of learned features: matches at the true place against the light, and time.

    python benchmarks/bench_keypoints.py [--town town01] [--features xfeat,xfeat-4096]
                                         [--matcher lighterglue-xfeat] [--k 0,8,10]
                                         [--places 12] [--repeats 3]
                                         [--viewpoint "8,37.5;13,40"]

At ``--places`` places along the route (half-way between gallery images, as bench_illumination's
queries), renders the gallery camera at each illumination level k and matches each query with the
gallery image nearest to it in the ground plane: the true place, the retrieval left out
(``--viewpoint``: the query camera raised by dz m and pitched down by the given degrees, at noon,
instead of the light's levels). For each feature preset (one keypoint budget each) it prints, per
level, the median keypoints and matches, the median and the least over the places of the matches
that hloc's check with the known poses keeps (each keypoint within 4 px of the other's epipolar
line, the maps' verification), and the matcher's median time per pair (the first place's pair at the
first level, after a warm-up, over ``--repeats``; learned stages run on one thread, as in a run's
worker). Whether a budget limits what the local features find where the retrieval is right, and what
it costs.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np

from bench_illumination import number_pairs, route_queries
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.preparation import prepare_gallery
from vlocbench.bench.towns import route_named, town_named
from vlocbench.bench.visual import camera_model
from vlocbench.loc.mapping import MappingConfig, fundamental_from_poses, verified
from vlocbench.loc.registry import build_features, build_matcher
from vlocbench.sim import Conditions, Illumination, Simulator, Viewpoint


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--town", default="town01")
    ap.add_argument("--features", default="xfeat,xfeat-4096", help="feature presets, one a budget")
    ap.add_argument("--matcher", default="lighterglue-xfeat")
    ap.add_argument("--k", default="0,8,10")
    ap.add_argument("--places", type=int, default=12)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--viewpoint", type=number_pairs, help='(dz m, pitch down deg) levels, "8,37.5;13,40"'
    )
    args = ap.parse_args()

    plan = load_experiment({"name": "bench", "towns": [args.town], "methods": ["sift"]})
    gallery = prepare_gallery(plan, args.town, progress=True)
    camera = dataclasses.replace(plan.spec.gallery.camera, name="query")
    model = camera_model(camera)
    centres = np.array([im.world_from_cam[:2, 3] for im in gallery.images])
    extractors = {name: build_features(name) for name in args.features.split(",")}
    matcher, check = build_matcher(args.matcher), MappingConfig()
    xy, yaws = route_queries(route_named(args.town), args.places)
    print(
        f"{args.town}, {args.places} places, {args.matcher}; per feature preset and level: median "
        "keypoints | matches | matches with the true geometry (median, least) | ms per pair"
    )
    pair_s: dict[str, float] = {}
    ks = [float(v) for v in args.k.split(",")]
    levels = [(f"k={k:g}", Conditions(illumination=Illumination(k=k))) for k in ks]
    if args.viewpoint:
        levels = [
            (f"{dz:g} m, {deg:g} deg", Conditions(viewpoint=Viewpoint(dz, deg)))
            for dz, deg in args.viewpoint
        ]
    with Simulator(town_named(args.town)) as sim:
        for label, conditions in levels:
            sim.set_conditions(conditions)
            rows: dict[str, list[tuple[int, int, int]]] = {name: [] for name in extractors}
            for (x, y), yaw in zip(xy, yaws):
                sim.teleport(float(x), float(y), float(yaw))
                query = sim.render([camera])[0]
                near = int(np.argmin(np.linalg.norm(centres - query.world_from_cam[:2, 3], axis=1)))
                image = gallery.images[near]
                F = fundamental_from_poses(model, query.world_from_cam, model, image.world_from_cam)
                mapped = gallery.load_image(gallery.names[near])
                for name, extractor in extractors.items():
                    fq, fg = extractor.extract(query.image), extractor.extract(mapped)
                    matches = matcher.match(fq, fg)
                    if name not in pair_s:  # warm-up, then the median of --repeats
                        times = []
                        for _ in range(args.repeats + 1):
                            start = time.perf_counter()
                            matcher.match(fq, fg)
                            times.append(time.perf_counter() - start)
                        pair_s[name] = statistics.median(times[1:])
                    xq, xg = fq.keypoints[matches[:, 0]], fg.keypoints[matches[:, 1]]
                    good = int(np.sum(verified(check, F, xq, xg))) if len(matches) else 0
                    rows[name].append((len(fq), len(matches), good))
            for name, r in rows.items():
                kps, found, good = np.array(r).T
                print(
                    f"{label} {name}: {np.median(kps):.0f} | {np.median(found):.0f} | "
                    f"{np.median(good):.0f}, {good.min()} | {1000 * pair_s[name]:.0f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
