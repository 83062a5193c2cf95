"""How many of a map's 3D points lie on the scene's surfaces, and what the others cost.

    python benchmarks/bench_map_points.py [--town town01] [--method sift] [--experiment FILE]
                                          [--queries 60] [--tolerance-m 0.5] [--keep DIR]

Checks the map's points against the scene's true surfaces (``vlocbench.bench.map_check``: a
depth render per gallery image; a point is on a surface when its depth at the keypoints that
observe it is within ``--tolerance-m`` or 5 % of the rendered depth, else behind or in front) for
the map of ``--town`` and ``--method`` (built under out/cache as an experiment would;
``--experiment`` as in ``bench_illumination.py``). It prints the shares by track length and by
the surface a point's first observation sees (``map_check.surface_kind``: a point off every
surface was triangulated from matches there, e.g. a ground texture's repeats), of each the share
whose observations see places over 1 m apart (false matches), and how far apart the two cameras
of each two-view point stand (a pair that joins look-alike places: far). Then it localizes
``--queries`` places of the route at noon (as ``bench_illumination.py`` places them) with the
map as built and with only its on-surface points, and prints T1 / T2 / T3 recall and wrong
answers of both: what the other points cost. ``--keep DIR`` keeps that second map (a
folder like the map's, its ``sfm/`` without the off-surface points), e.g. to drive with it in
place of the first.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from collections import defaultdict
from pathlib import Path

import numpy as np
import pycolmap

from bench_illumination import method_plan, route_queries
from vlocbench.bench.localizer import LocalizationQuery
from vlocbench.bench.map_check import PLACES, SURFACES, check_points, surface_kind
from vlocbench.bench.metrics import confident_wrong, recall
from vlocbench.bench.preparation import prepare_maps
from vlocbench.bench.towns import route_named, town_named
from vlocbench.bench.visual import VisualLocalizer
from vlocbench.geometry import planar_pose, pose_error
from vlocbench.loc.gallery import Gallery
from vlocbench.loc.mapping import map_info
from vlocbench.sim import Conditions, Simulator


def on_surface_map(map_dir: Path, keep: set[int], out: Path) -> None:
    """``out``: the map's files (linked) with an ``sfm/`` holding only the points ``keep``."""
    out.mkdir(parents=True, exist_ok=True)
    for entry in map_dir.iterdir():
        if entry.name != "sfm" and not (out / entry.name).exists():
            (out / entry.name).symlink_to(entry.resolve())
    rec = pycolmap.Reconstruction(map_dir / "sfm")
    for pid in [p for p in rec.points3D if p not in keep]:
        rec.delete_point3D(pid)
    (out / "sfm").mkdir(exist_ok=True)
    rec.write(out / "sfm")


def place_shares(counts: dict[str, int]) -> str:
    """``points | on / behind / in front (%)`` of points counted by place."""
    total = sum(counts.values())
    return f"{total} | " + " / ".join(f"{100 * counts[k] / max(total, 1):.1f}" for k in PLACES)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--town", default="town01")
    ap.add_argument("--method", default="sift")
    ap.add_argument("--experiment", type=Path, help="the maps of this experiment")
    ap.add_argument("--queries", type=int, default=60)
    ap.add_argument("--tolerance-m", type=float, default=0.5)
    ap.add_argument("--keep", type=Path, help="keep the map of on-surface points here")
    args = ap.parse_args()
    plan = method_plan(args.experiment, args.town, args.method)
    map_dir = Path(prepare_maps(plan, progress=True)[(args.town, args.method)])
    gallery = Gallery.load(map_info(map_dir)[1])
    rec = pycolmap.Reconstruction(map_dir / "sfm")
    with Simulator(town_named(args.town)) as sim:
        check = check_points(rec, gallery, sim.renderer)
        places = check.places(args.tolerance_m)
        counts: dict[str, dict[str, int]] = defaultdict(lambda: dict.fromkeys(PLACES, 0))
        # points whose observations see places over 1 m apart: false matches, by place
        apart: dict[str, dict[str, int]] = defaultdict(lambda: dict.fromkeys(PLACES, 0))
        # how far apart the two cameras of each two-view point stand, by place: look-alike
        # places joined by a pair stand far apart
        baseline_m: dict[str, list[float]] = {place: [] for place in PLACES}
        for pid, place in places.items():
            track = rec.points3D[pid].track
            n = track.length()
            for key in ("all", "2" if n == 2 else "3-4" if n <= 4 else "5+"):
                counts[key][place] += 1
                apart[key][place] += check.spread_m[pid] > 1.0
            if n == 2:
                a, b = (rec.images[e.image_id].projection_center() for e in track.elements)
                baseline_m[place].append(float(np.linalg.norm(a - b)))
        print(f"{args.town}, {args.method}: {map_dir}")
        print(f"{len(places)} points; tolerance {args.tolerance_m} m or 5 % of the depth")
        print(
            "track length | points | on / behind / in front (%) | "
            "of these, seeing places over 1 m apart (%)"
        )
        for key in ("all", "2", "3-4", "5+"):
            seen_apart = (100 * apart[key][k] / max(counts[key][k], 1) for k in PLACES)
            print(
                f"{key} | {place_shares(counts[key])} | {' / '.join(f'{a:.1f}' for a in seen_apart)}"
            )
        print("two-view points | their cameras apart, median (m) | over 20 m apart (%)")
        for place, d in baseline_m.items():
            if d:
                print(f"{place} | {np.median(d):.1f} | {100 * np.mean(np.array(d) > 20):.1f}")
        print("seen on | points | on / behind / in front (%) | of all off-surface points (%)")
        by_surface: dict[str, dict[str, int]] = defaultdict(lambda: dict.fromkeys(PLACES, 0))
        for pid, place in places.items():
            by_surface[surface_kind(sim.town, check.seen_xyz_m[pid])][place] += 1
        off_total = sum(c[k] for c in by_surface.values() for k in PLACES[1:])
        for surface in SURFACES:
            c = by_surface[surface]
            off = 100 * (c[PLACES[1]] + c[PLACES[2]]) / max(off_total, 1)
            print(f"{surface} | {place_shares(c)} | {off:.1f}")
        on = {pid for pid, place in places.items() if place == "on"}

        camera = dataclasses.replace(plan.spec.gallery.camera, name="query")
        config = plan.spec.methods[0].localizer
        with tempfile.TemporaryDirectory() as tmp:
            clean_dir = args.keep or Path(tmp) / "on-surface"
            on_surface_map(map_dir, on, clean_dir)
            maps = {"as built": map_dir, "on-surface points only": clean_dir}
            localizers = {
                k: VisualLocalizer(d, (camera,), config, name=args.method) for k, d in maps.items()
            }
            errors: dict[str, list[tuple[float, float]]] = {k: [] for k in maps}
            sim.set_conditions(Conditions())
            xy, yaws = route_queries(route_named(args.town, plan.spec.route_length_m), args.queries)
            for (x, y), h in zip(xy, yaws):
                sim.teleport(float(x), float(y), float(h))
                truth = planar_pose(float(x), float(y), float(h))
                frames = tuple(sim.render([camera]))
                for key, localizer in localizers.items():
                    e = localizer.localize(LocalizationQuery(0.0, frames, truth))
                    err = (
                        pose_error(truth, e.world_from_vehicle)
                        if e.success and e.world_from_vehicle is not None
                        else (np.nan, np.nan)
                    )
                    errors[key].append(err)
        print(f"{args.queries} queries at noon | T1 / T2 / T3 (%) | wrong (%)")
        for key, errs in errors.items():
            pos, rot = (np.array(v) for v in zip(*errs))
            rec_t = " / ".join(f"{100 * r:.1f}" for r in recall(pos, rot)[:3])
            print(f"{key} | {rec_t} | {100 * confident_wrong(pos, rot):.1f}")


if __name__ == "__main__":
    main()
