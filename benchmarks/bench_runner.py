"""Throughput of the benchmark runner: episodes per hour with 1 and 2 workers, and the harness's
overhead (store, scheduling, transfers, idle workers at the end) as a share of episode time.

    python benchmarks/bench_runner.py [--workers 1,2] [--repeats 3] [--out out/bench_runner]
                                      [--one-thread] [--antialias] [--reps-per-worker 0]

One worker runs in the driver process, whose OpenCV, torch and renderer use every core; a pool
worker uses one thread of each. ``--one-thread`` limits this process as a pool worker is limited,
so that ``--workers 1 --one-thread`` shows what one pool worker does alone (run it on its own:
the limits hold for the whole process).

The experiment is fixed: the first 150 m of town10's route, SIFT + VLAD at 800x600, k in {0, 3, 6,
9}, one repetition (4 recall, 4 failure and 1 odometry-only episodes). Its gallery and map are built
once (a warm-up run) and reused; each timed run starts from an empty store. Target (issue 5):
overhead under 5 %. ``--reps-per-worker R`` runs R repetitions per worker instead (4R failure and R
odometry-only episodes a worker), so that many workers have as much to do as one: the scaling on a
machine with many cores (issue 29: 16 workers at least 12x one).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
from pathlib import Path

import cv2

from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.runner import run_experiment
from vlocbench.bench.worker import WORKER_THREADS_ENV

EXPERIMENT = {
    "name": "bench_runner",
    "towns": ["town10"],
    "route_length_m": 150,
    "methods": ["sift"],
    "sweep": {"illumination.k": [0, 3, 6, 9]},
    "repetitions": 1,
    "baseline_repetitions": 1,  # one odometry-only drive a repetition, as the other episodes
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("out/bench_runner"))
    ap.add_argument("--one-thread", action="store_true", help="this process as a pool worker")
    ap.add_argument("--antialias", action="store_true", help="render with Camera(antialias=True)")
    ap.add_argument(
        "--reps-per-worker", type=int, default=0, help="repetitions per worker (0: one in all)"
    )
    args = ap.parse_args()
    experiment = {**EXPERIMENT, "gallery": {"camera": {"antialias": args.antialias}}}
    if args.one_thread:
        if any(os.environ.get(k) != v for k, v in WORKER_THREADS_ENV.items()):
            # numpy's OpenBLAS took its threads as numpy loaded: start again as a pool worker does
            env = {**os.environ, **WORKER_THREADS_ENV}
            os.execve(sys.executable, [sys.executable, *sys.argv], env)
        cv2.setNumThreads(1)
    plan = load_experiment(
        {**experiment, "output": str(args.out / "warmup"), "cache": str(args.out / "cache")}
    )
    shutil.rmtree(plan.output_dir, ignore_errors=True)
    run_experiment(plan, progress=False)  # gallery, map, imports, caches
    first: float | None = None  # episodes/hour of the first worker count
    for workers in (int(w) for w in args.workers.split(",")):
        rates, overheads, stores = [], [], []
        repetitions = max(1, args.reps_per_worker * workers)
        for k in range(args.repeats):
            out = args.out / f"w{workers}-{k}"
            shutil.rmtree(out, ignore_errors=True)
            s = run_experiment(
                load_experiment(
                    {
                        **experiment,
                        "repetitions": repetitions,
                        "output": str(out),
                        "cache": str(args.out / "cache"),
                    }
                ),
                workers=workers,
                progress=False,
            )
            rates.append(s.finished / s.episodes_wall_s * 3600)
            if s.harness_overhead is not None:  # None: a worker died
                overheads.append(100 * s.harness_overhead)
            stores.append(100 * s.store_overhead)
        rate = statistics.median(rates)
        first = first or rate
        print(
            f"{workers} worker(s): {rate:.0f} episodes/hour ({rate / first:.2f}x the first) "
            f"({s.finished} episodes of about {s.episode_s / s.finished:.1f} s in the worker); "
            f"harness overhead {statistics.median(overheads):.1f} % of episode time "
            f"(writing results {statistics.median(stores):.2f} %; the rest is scheduling, "
            f"transfers and workers idle at the end; median of {args.repeats}, runs: "
            + ", ".join(f"{v:.1f}" for v in overheads)
            + ")"
        )


if __name__ == "__main__":
    main()
