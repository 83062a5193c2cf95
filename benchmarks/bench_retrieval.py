"""Retrieval alone under a changed viewpoint or changed conditions: Recall@1 / @5 of global
descriptors.

    python benchmarks/bench_retrieval.py [--experiment experiments/paper/viewpoint.yaml]
                                         [--town town01] [--retrievals effnet-gem,vlad,vlad:xfeat]
                                         [--viewpoint "0,0;2,10;4,22.5;8,37.5"] [--queries 40]
                                         [--setups experiments/paper/weather.yaml]

The experiment's gallery of ``--town`` (captured unless cached) is described by each registered
global descriptor, ``NAME`` over the SIFT features or ``NAME:FEATURES`` over a feature preset's
(VLAD learns its vocabulary from those of the gallery first); queries are rendered at ``--queries``
places along the route (half-way between gallery images), the query camera raised and pitched
down by each ``--viewpoint`` level, or under the conditions of each setup of ``--setups FILE``; a
query counts for Recall@N when one of its N most similar gallery images was taken within 10 m of
the query camera. No map, no PnP: which stand-in for the paper's NetVLAD / AP-GeM keeps finding
the place.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from bench_illumination import route_queries
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.preparation import prepare_gallery
from vlocbench.bench.towns import route_named, town_named
from vlocbench.loc.registry import build_features, build_retrieval
from vlocbench.sim import Conditions, Simulator, Viewpoint

RADIUS_M = 10.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--experiment", type=Path, default=Path("experiments/paper/viewpoint.yaml"))
    ap.add_argument("--town", default="town01")
    ap.add_argument("--retrievals", default="effnet-gem,vlad")
    ap.add_argument("--viewpoint", default="0,0;2,10;4,22.5;8,37.5")
    ap.add_argument("--queries", type=int, default=40)
    ap.add_argument("--setups", type=Path, help="the conditions of this experiment's setups")
    args = ap.parse_args()
    plan = load_experiment(args.experiment).only([args.town])
    gallery = prepare_gallery(plan, args.town)
    names = args.retrievals.split(",")
    over = {name: [*name.split(":"), "sift"][1] for name in names}  # its local features
    extractors = {f: build_features(f) for f in set(over.values())}
    descriptors = {name: build_retrieval(name.split(":")[0]) for name in names}
    t0 = time.perf_counter()
    images = [gallery.load_image(n) for n in gallery.names]
    features = {f: [e.extract(im) for im in images] for f, e in extractors.items()}
    described = {}
    for name, d in descriptors.items():
        assert d is not None, f"{name} is not a global descriptor"
        d.fit(features[over[name]])
        described[name] = np.stack(
            [d.describe(im, f) for im, f in zip(images, features[over[name]])]
        )
    where = np.array([im.world_from_cam[:2, 3] for im in gallery.images])
    print(
        f"{args.town}: {len(images)} gallery images described in {time.perf_counter() - t0:.0f} s"
    )
    camera = dataclasses.replace(plan.spec.gallery.camera, name="query")
    xy, yaws = route_queries(route_named(args.town, plan.spec.route_length_m), args.queries)
    if args.setups:
        levels = [(s.label, s.conditions) for s in load_experiment(args.setups).setups]
    else:
        levels = []
        for level in args.viewpoint.split(";"):
            dz, pitch = (float(v) for v in level.split(","))
            levels.append((f"({dz:g}, {pitch:g})", Conditions(viewpoint=Viewpoint(dz, pitch))))
    print("level | " + " | ".join(f"{n} R@1 / R@5 (%)" for n in names))
    sim = Simulator(town_named(args.town))
    try:
        for label, conditions in levels:
            sim.set_conditions(conditions)
            hits = {n: np.zeros(2) for n in names}
            for (x, y), yaw in zip(xy, yaws):
                sim.teleport(float(x), float(y), float(yaw))
                [frame] = sim.render([camera])
                f = {preset: e.extract(frame.image) for preset, e in extractors.items()}
                for n, d in descriptors.items():
                    assert d is not None
                    query = d.describe(frame.image, f[over[n]])
                    order = np.argsort(-(described[n] @ query))[:5]
                    near = np.linalg.norm(where[order] - frame.world_from_cam[:2, 3], axis=1)
                    hits[n] += [near[0] <= RADIUS_M, (near <= RADIUS_M).any()]
            cells = [" / ".join(f"{100 * v / len(xy):.1f}" for v in hits[n]) for n in names]
            print(f"{label} | " + " | ".join(cells), flush=True)
    finally:
        sim.close()


if __name__ == "__main__":
    main()
