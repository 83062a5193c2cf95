"""Towns drawn from a distribution: how long drawing a spec and generating its town takes.

    python benchmarks/bench_generation.py [--count 8] [--seed 100] [--runs 3]

Target (issue 29): a town in at most 10 s. For each style, ``--count`` towns of the set
``--seed``: the median over ``--runs`` runs (after a warm-up) of drawing the spec
(``load_town_spec``: the style's ranges and a route search) and of generating the town and its
lane graph; the slowest town of the set; and building its MuJoCo scene (``Simulator``, which an
episode does once per worker and town), the median over the set's towns.
"""

from __future__ import annotations

import argparse
import statistics
import time

from vlocbench.sim import Simulator
from vlocbench.sim.generation import STYLES, TownSet
from vlocbench.sim.town import generate_town, load_town_spec


def _timed(name: str) -> tuple[float, float]:
    t0 = time.perf_counter()
    spec = load_town_spec(name)
    t1 = time.perf_counter()
    town = generate_town(spec)
    town.lane_graph  # noqa: B018 (built on first use; an episode needs it)
    return t1 - t0, time.perf_counter() - t1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=8)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    print(
        "style | towns | draw spec, median (ms) | generate, median (ms) | slowest town (ms)"
        " | scene, median (s)"
    )
    for style in STYLES:
        names = TownSet(args.count, style, args.seed).names()
        _timed(names[0])  # warm-up: imports, caches
        per_town = [[_timed(n) for _ in range(args.runs)] for n in names]
        draw = statistics.median(d for runs in per_town for d, _ in runs)
        build = statistics.median(b for runs in per_town for _, b in runs)
        slowest = max(statistics.median(d + b for d, b in runs) for runs in per_town)
        scene = []
        for name in names:
            t0 = time.perf_counter()
            Simulator(generate_town(load_town_spec(name))).close()
            scene.append(time.perf_counter() - t0)
        print(
            f"{style} | {len(names)} | {1000 * draw:.0f} | {1000 * build:.0f} | {1000 * slowest:.0f}"
            f" | {statistics.median(scene):.1f}"
        )


if __name__ == "__main__":
    main()
