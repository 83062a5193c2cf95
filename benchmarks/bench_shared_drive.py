"""What recall drives save by sharing one drive across methods (issue 26): the episode phase of
a recall-only experiment with two methods, each drive shared or driven alone.

    python benchmarks/bench_shared_drive.py [--repeats 3] [--workers 1] [--out out/bench_shared_drive]

The experiment is fixed: the first 150 m of town10's route at 800x600, the demo's methods
(``sift``, and ``sift`` gated at ``localizer.min_inliers: 12``), k in {0, 8}, recall episodes only
(4 in all). Its
gallery and map are built once (a warm-up run) and reused; each timed run starts from an empty
store; shared and alone alternate. Prints the median episode-phase time of each way, the saving,
and whether both stored the same results.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
from pathlib import Path

from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.runner import run_experiment
from vlocbench.bench.store import ResultStore
from vlocbench.config import load_yaml

DEMO = Path(__file__).parents[1] / "experiments" / "demo.yaml"

EXPERIMENT = {
    "name": "bench_shared_drive",
    "towns": ["town10"],
    "route_length_m": 150,
    "methods": load_yaml(DEMO)["methods"],  # sift, and sift gated at 12 inliers
    "sweep": {"illumination.k": [0, 8]},
    "repetitions": 1,
    "failure": False,
    "baseline": False,
}
# what a recall episode stores that does not depend on timing
COMPARED = ("queries", "recall", "recall_ekf", "place_recall", "confident_wrong")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path("out/bench_shared_drive"))
    args = ap.parse_args()

    def run(name: str, share: bool) -> tuple[float, dict[str, tuple[object, ...]]]:
        out = args.out / name
        shutil.rmtree(out, ignore_errors=True)
        plan = load_experiment({**EXPERIMENT, "output": str(out), "cache": str(args.out / "cache")})
        s = run_experiment(plan, workers=args.workers, progress=False, share_drives=share)
        with ResultStore(out, plan.name) as store:
            stored = {r.key: tuple(getattr(r.metrics, f) for f in COMPARED) for r in store.rows()}
        return s.episodes_wall_s, stored

    run("warmup", True)  # gallery, map, imports, caches
    times: dict[bool, list[float]] = {True: [], False: []}
    results: dict[bool, dict[str, tuple[object, ...]]] = {}
    for k in range(args.repeats):
        for share in (True, False):
            wall_s, results[share] = run(f"{'shared' if share else 'alone'}-{k}", share)
            times[share].append(wall_s)
    shared, alone = (statistics.median(times[s]) for s in (True, False))
    print(
        f"4 recall episodes (2 methods x 2 setups), {args.workers} worker(s), {args.repeats} runs:"
    )
    print(f"  alone   {alone:6.1f} s  (runs: {', '.join(f'{t:.1f}' for t in times[False])})")
    print(f"  shared  {shared:6.1f} s  (runs: {', '.join(f'{t:.1f}' for t in times[True])})")
    print(f"  saved   {alone - shared:6.1f} s, {100 * (1 - shared / alone):.0f} %")
    print(f"  same stored results: {'yes' if results[True] == results[False] else 'NO'}")


if __name__ == "__main__":
    main()
