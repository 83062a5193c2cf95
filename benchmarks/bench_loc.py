"""Visual localization: map building, per-query speed with per-stage times, and recall.

    python benchmarks/bench_loc.py [--town town01] [--methods sift,orb-teblid,aliked-lightglue]
                                   [--k 0,6] [--every 1] [--speed-k 5] [--out out/bench_loc]
                                   [--confident-inliers 0] [--route-length 0]

Galleries and maps are built once under --out and reused. Recall: the town's route driven on ground
truth with queries at 2 Hz (every --every-th query kept), at each illumination level k; a failed
localization is a miss. Speed: 800x600 queries at k = --speed-k, the median per query after a
warm-up, and the median of each stage. Targets (issue 4): recall at (0.25 m, 2 deg) >= 90 % for SIFT
and >= 95 % for ALIKED + LightGlue on town01 at k = 0; SIFT <= 150 ms and ALIKED + LightGlue <= 1.5 s
per query; the town01 SIFT map in <= 10 minutes.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from vlocbench.bench import EpisodeConfig, plan_town_route, run_episode
from vlocbench.bench.gallery_capture import capture_gallery
from vlocbench.bench.metrics import recall
from vlocbench.bench.visual import VisualLocalizer, camera_model
from vlocbench.loc.gallery import GALLERY_FILE, Gallery
from vlocbench.loc.localizer import LocalizerConfig, MapLocalizer
from vlocbench.loc.mapping import MAP_FILE, MappingConfig, build_map
from vlocbench.loc.registry import method_conf
from vlocbench.sim import Conditions, Illumination, Simulator, gallery_camera
from vlocbench.sim.scene import SCENE_VERSION
from vlocbench.sim.town import generate_town, load_town_spec


class EveryNth(VisualLocalizer):
    """Answers every n-th query, fails the rest without work (a cheaper recall estimate)."""

    def __init__(self, *args, every: int = 1, **kwargs):
        super().__init__(*args, **kwargs)
        self.every, self.count = every, 0

    def localize(self, query):
        self.count += 1
        if (self.count - 1) % self.every:
            from vlocbench.bench.localizer import PoseEstimate

            return PoseEstimate.failure("skipped")
        return super().localize(query)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--town", default="town01")
    ap.add_argument("--methods", default="sift,orb-teblid")
    ap.add_argument("--k", default="0,6")
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--speed-k", type=float, default=5.0)
    ap.add_argument("--speed-queries", type=int, default=20)
    ap.add_argument("--num-pairs", type=int, default=25)
    ap.add_argument("--out", type=Path, default=Path("out/bench_loc"))
    ap.add_argument("--route-length", type=float, default=0.0, help="metres of route, 0: all")
    ap.add_argument(
        "--confident-inliers", type=int, default=0, help="LocalizerConfig.confident_inliers"
    )
    args = ap.parse_args()
    town = generate_town(load_town_spec(args.town))
    # --route-length: the first metres only (a quicker gallery, map and recall drive)
    path = plan_town_route(town).head(args.route_length)
    cam = gallery_camera()
    # a new look of the town, a new gallery
    stem = f"{town.name}-v{SCENE_VERSION}" + (
        f"-{args.route_length:g}m" if args.route_length else ""
    )
    gallery_dir = args.out / f"{stem}-gallery"
    if not (gallery_dir / GALLERY_FILE).exists():
        sim = Simulator(town)
        t = time.perf_counter()
        capture_gallery(sim, path, (cam,), gallery_dir)
        sim.close()
        print(f"{town.name}: gallery captured in {time.perf_counter() - t:.0f} s")
    gallery = Gallery.load(gallery_dir)
    print(f"{town.name}: gallery of {len(gallery)} images, route {path.length_m:.0f} m")
    for method in args.methods.split(","):
        map_dir = args.out / f"{stem}-{method}-p{args.num_pairs}"
        fresh = not (map_dir / MAP_FILE).exists()
        report = build_map(
            gallery, method_conf(method), map_dir, MappingConfig(num_pairs=args.num_pairs)
        )
        print(
            f"{method}: map {report.points} points, track length {report.mean_track_length:.2f}, "
            f"reprojection {report.mean_reprojection_error_px:.2f} px"
            + (
                f"; built in {sum(report.seconds.values()) / 60:.1f} min ("
                + ", ".join(f"{k} {v:.0f} s" for k, v in report.seconds.items())
                + ")"
                if fresh
                else ""
            )
        )
        # speed: queries along the route at k = speed_k
        sim = Simulator(town, Conditions(illumination=Illumination(k=args.speed_k)))
        loc_config = LocalizerConfig(confident_inliers=args.confident_inliers)
        localizer = MapLocalizer(map_dir, loc_config)
        model = camera_model(cam)
        idx = np.linspace(5, len(path) - 5, args.speed_queries + 1).astype(int)
        totals: list[float] = []
        stages: dict[str, list[float]] = {}
        for n, j in enumerate(idx):
            sim.teleport(float(path.xy[j, 0]), float(path.xy[j, 1]), float(path.yaw_rad[j]))
            image = sim.render([cam])[0].image
            t = time.perf_counter()
            result = localizer.localize(image, model)
            if n == 0:
                continue  # warm-up
            totals.append(time.perf_counter() - t)
            for stage, v in result.seconds.items():
                stages.setdefault(stage, []).append(v)
        sim.close()
        print(
            f"  speed at k={args.speed_k:g}, 800x600: median {1000 * statistics.median(totals):.0f} ms "
            f"per query ("
            + ", ".join(f"{k} {1000 * statistics.median(v):.0f} ms" for k, v in stages.items())
            + ")"
        )
        # recall along the ground-truth drive
        for k in (float(v) for v in args.k.split(",")):
            sim = Simulator(town, Conditions(illumination=Illumination(k=k)))
            loc = EveryNth(map_dir, (cam,), loc_config, every=args.every, name=method)
            r = run_episode(sim, path, loc, EpisodeConfig(mode="ground_truth"))
            sim.close()
            recs = [x for x in r.localizations if x.reason != "skipped"]
            fractions = recall(
                np.array([x.position_error_m for x in recs]),
                np.array([x.yaw_error_deg for x in recs]),
            )
            print(
                f"  recall k={k:g} ({len(recs)} queries): "
                + " / ".join(f"{100 * v:.1f}" for v in fractions)
                + " % at (0.25 m, 2 deg) / (0.5 m, 5 deg) / (5 m, 10 deg) / (20 m, 180 deg)"
            )


if __name__ == "__main__":
    main()
