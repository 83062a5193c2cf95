"""A learned map's build in one process against one whose features and matches are made on a pool
of worker processes.

    python benchmarks/bench_map_build.py [--town town10] [--method xfeat-lighterglue]
                                         [--images 60] [--num-pairs 5] [--workers 1,2]
                                         [--repeats 3]

Takes the first ``--images`` images of the town's gallery (out/cache, as an experiment captures
them), then builds the method's map from scratch, a warm-up first, ``--repeats`` times for each
count of ``--workers`` (1: in this process, as before; more: a ``MatchPool`` of that many spawned
processes, one thread each, started before the timing, as ``vlocbench run`` and
``vlocbench build-map --workers`` start theirs), and prints the median seconds of the whole build
and of its feature and matching stages, with each build's pairs and points (the same for every
count when the features and matches are).
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import tempfile
from pathlib import Path

from vlocbench.bench.executors import worker_pool
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.preparation import prepare_gallery
from vlocbench.loc.mapping import MappingConfig, MatchPool, build_map
from vlocbench.loc.registry import method_conf


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--town", default="town10")
    ap.add_argument("--method", default="xfeat-lighterglue")
    ap.add_argument("--images", type=int, default=60)
    ap.add_argument("--num-pairs", type=int, default=5)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    plan = load_experiment({"name": "bench", "towns": [args.town], "methods": ["sift"]})
    gallery = prepare_gallery(plan, args.town, progress=True)
    root = Path(tempfile.mkdtemp(prefix="bench_map_build_"))
    small = gallery.head(args.images, root / "gallery")
    conf, mapping = method_conf(args.method), MappingConfig(num_pairs=args.num_pairs)
    print(f"{args.town}, {args.method}: {len(small)} images, {args.num_pairs} pairs an image")
    print("workers | build s (median) | features s (median) | matching s (median) | pairs | points")
    for workers in (int(w) for w in args.workers.split(",")):
        with contextlib.ExitStack() as stack:
            executor = stack.enter_context(worker_pool(workers)) if workers > 1 else None
            pool = MatchPool(executor, workers) if executor else None
            builds = [
                build_map(small, conf, root / f"map{workers}", mapping, overwrite=True, pool=pool)
                for _ in range(args.repeats + 1)  # the first warms up (the pool's imports too)
            ][1:]
        total = statistics.median(sum(b.seconds.values()) for b in builds)
        stage = {
            s: statistics.median(b.seconds[s] for b in builds) for s in ("features", "matching")
        }
        print(
            f"{workers} | {total:.1f} | {stage['features']:.1f} | {stage['matching']:.1f} | "
            f"{builds[0].pairs} | {builds[0].points}"
        )


if __name__ == "__main__":
    main()
