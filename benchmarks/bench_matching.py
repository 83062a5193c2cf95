"""LightGlue per image pair: one pair at a time against batches, with and without point pruning.

    python benchmarks/bench_matching.py [--town town01] [--features xfeat]
                                        [--matcher lighterglue-xfeat] [--pairs 16] [--repeats 3]

Extracts features of consecutive gallery images of the town (out/cache, as an experiment
captures them), warms up, then prints the median time per pair over ``--repeats`` runs of
``--pairs`` pairs: ``match`` one pair at a time, ``match_many`` in batches of 4 and 16 (what map
building uses), and the same batches with point pruning off (``width_confidence`` -1), the only
way kornia runs a batch as one forward pass on the CPU. The device is the learned stages' default
(``VLOCBENCH_DEVICE`` chooses).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.preparation import prepare_gallery
from vlocbench.loc.learned import LightGlueMatcher
from vlocbench.loc.registry import build_features, build_matcher


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--town", default="town01")
    ap.add_argument("--features", default="xfeat")
    ap.add_argument("--matcher", default="lighterglue-xfeat")
    ap.add_argument("--pairs", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    plan = load_experiment({"name": "bench", "towns": [args.town], "methods": ["sift"]})
    gallery = prepare_gallery(plan, args.town, progress=True)
    extractor = build_features(args.features)
    first = len(gallery) // 3  # the route's middle, away from its ends
    feats = [
        extractor.extract(gallery.load_image(gallery.names[first + k]))
        for k in range(args.pairs + 1)
    ]
    pairs = [(feats[k], feats[k + 1]) for k in range(args.pairs)]
    matcher = build_matcher(args.matcher)
    if not isinstance(matcher, LightGlueMatcher):
        raise SystemExit(f"{args.matcher} is not a LightGlue-type matcher")
    print(f"{args.matcher} on {matcher.device}, keypoints {sorted({len(f) for f in feats})}")

    own_width = matcher.net.conf.width_confidence  # the preset's pruning (LighterGlue: 0.95)

    def batched(size: int, prune: bool) -> Callable[[], object]:
        def run() -> object:
            matcher.batch_size = size
            matcher.net.conf.width_confidence = own_width if prune else -1
            try:
                return matcher.match_many(pairs)
            finally:
                matcher.net.conf.width_confidence = own_width

        return run

    variants: dict[str, Callable[[], object]] = {
        "one pair at a time": lambda: [matcher.match(a, b) for a, b in pairs],
        "batches of 4": batched(4, True),
        "batches of 16": batched(16, True),
        "batches of 4, no pruning": batched(4, False),
        "batches of 16, no pruning": batched(16, False),
    }
    variants["one pair at a time"]()  # warm-up
    for name, run in variants.items():
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            run()
            times.append((time.perf_counter() - start) / len(pairs))
        print(f"{name:28s} {1000 * statistics.median(times):7.1f} ms per pair")


if __name__ == "__main__":
    main()
