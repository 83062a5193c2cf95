"""Retrieval alone under a changed viewpoint: Recall@1 / @5 of global descriptors.

    python benchmarks/bench_retrieval.py [--experiment experiments/paper/viewpoint.yaml]
                                         [--town town01] [--retrievals effnet-gem,vlad]
                                         [--viewpoint "0,0;2,10;4,22.5;8,37.5"] [--queries 40]

The experiment's gallery of ``--town`` (captured unless cached) is described by each registered
global descriptor (VLAD learns its vocabulary from the gallery's SIFT features first); queries are
rendered at ``--queries`` places along the route (half-way between gallery images), the query
camera raised and pitched down by each ``--viewpoint`` level; a query counts for Recall@N when one
of its N most similar gallery images was taken within 10 m of the query camera. No map, no PnP:
which stand-in for the paper's NetVLAD / AP-GeM keeps finding the place.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

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
    args = ap.parse_args()
    plan = load_experiment(args.experiment).only([args.town])
    gallery = prepare_gallery(plan, args.town)
    sift = build_features("sift")
    names = args.retrievals.split(",")
    descriptors = {name: build_retrieval(name) for name in names}
    t0 = time.perf_counter()
    images = [gallery.load_image(n) for n in gallery.names]
    features = [sift.extract(im) for im in images]
    described = {}
    for name, d in descriptors.items():
        assert d is not None, f"{name} is not a global descriptor"
        d.fit(features)
        described[name] = np.stack([d.describe(im, f) for im, f in zip(images, features)])
    where = np.array([im.world_from_cam[:2, 3] for im in gallery.images])
    print(
        f"{args.town}: {len(images)} gallery images described in {time.perf_counter() - t0:.0f} s"
    )
    route = route_named(args.town)
    camera = dataclasses.replace(plan.spec.gallery.camera, name="query")
    s = np.round(np.linspace(10.0, route.length_m - 10.0, args.queries) / 2.0) * 2.0 + 1.0
    xy = np.stack([np.interp(s, route.s_m, route.xy[:, i]) for i in (0, 1)], 1)
    yaws = np.interp(s, route.s_m, np.unwrap(route.yaw_rad))
    print("(dz m, pitch deg) | " + " | ".join(f"{n} R@1 / R@5 (%)" for n in names))
    sim = Simulator(town_named(args.town))
    try:
        for level in args.viewpoint.split(";"):
            dz, pitch = (float(v) for v in level.split(","))
            sim.set_conditions(Conditions(viewpoint=Viewpoint(dz, pitch)))
            hits = {n: np.zeros(2) for n in names}
            for (x, y), yaw in zip(xy, yaws):
                sim.teleport(float(x), float(y), float(yaw))
                [frame] = sim.render([camera])
                f = sift.extract(frame.image)
                for n, d in descriptors.items():
                    assert d is not None
                    order = np.argsort(-(described[n] @ d.describe(frame.image, f)))[:5]
                    near = np.linalg.norm(where[order] - frame.world_from_cam[:2, 3], axis=1)
                    hits[n] += [near[0] <= RADIUS_M, (near <= RADIUS_M).any()]
            cells = [" / ".join(f"{100 * v / len(xy):.1f}" for v in hits[n]) for n in names]
            print(f"({dz:g}, {pitch:g}) | " + " | ".join(cells), flush=True)
    finally:
        sim.close()


if __name__ == "__main__":
    main()
