"""Navigation stack and closed-loop episodes: speed, odometry drift, ground-truth tracking and the
wheel-odometry-only failure rate.

Targets (issue 3): an odometry-only episode of town01's route >= 50x real time without rendering
and >= 5x with one 800x600 camera rendered at 2 Hz; on ground truth no failure and mean tracking
error < 0.3 m in both towns; the odometry-only failure rate over 5 seeds, beside the paper's 17.9
(Town01) and 9.8 (Town10) per km. Speeds are medians of 3 runs after a warm-up.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence

import numpy as np

from vlocbench.bench import (
    EpisodeConfig,
    LocalizationQuery,
    PoseEstimate,
    plan_town_route,
    run_episode,
)
from vlocbench.geometry import wrap_angle
from vlocbench.nav import WheelOdometry, dead_reckoning_drift
from vlocbench.sim import Camera, Simulator, gallery_camera
from vlocbench.sim.town import generate_town, load_town_spec

PAPER_ODOMETRY_RATE = {"town01": 17.9, "town10": 9.8}


class RenderOnly:
    """Renders the gallery camera at every query and localizes nothing: the cost of the images."""

    name = "render-only"
    uses_ground_truth = False

    @property
    def cameras(self) -> Sequence[Camera]:
        return (gallery_camera(),)

    def reset(self, seed: int) -> None:
        pass

    def close(self) -> None:
        pass

    def localize(self, query: LocalizationQuery) -> PoseEstimate:
        assert query.frames[0].image.shape == (600, 800, 3)
        return PoseEstimate.failure("no method")


def median_rtf(sim, path, localizer, runs=3) -> float:
    config = EpisodeConfig(seed=0)
    run_episode(sim, path, localizer, config)  # warm-up
    return statistics.median(
        run_episode(sim, path, localizer, config).real_time_factor for _ in range(runs)
    )


def main() -> None:
    for name in ("town01", "town10"):
        town = generate_town(load_town_spec(name))
        sim = Simulator(town)
        path = plan_town_route(town)
        gt = run_episode(sim, path, None, EpisodeConfig(mode="ground_truth"))
        print(
            f"{name}: route {path.length_m:.0f} m; ground truth: {gt.failures} failures, mean "
            f"tracking error {gt.tracking_error_mean_m:.3f} m, {gt.sim_time_s:.0f} s"
        )
        tr = gt.trajectory
        poses = np.stack([tr.true_x_m, tr.true_y_m, tr.true_yaw_rad], axis=1)
        dt = sim.dt_s
        speeds = np.hypot(np.diff(tr.true_x_m), np.diff(tr.true_y_m)) / dt
        yaw_rates = np.asarray(wrap_angle(np.diff(tr.true_yaw_rad))) / dt
        drifts = [
            dead_reckoning_drift(poses, speeds, yaw_rates, dt, WheelOdometry(seed=s))
            for s in range(20)
        ]
        print(
            f"  odometry dead-reckoning drift over the route (20 seeds, median): "
            f"{statistics.median(d.position_percent for d in drifts):.1f} % of distance, "
            f"{statistics.median(d.yaw_deg_per_m for d in drifts):.3f} deg/m "
            f"(paper: about 8.5 %, 0.4 deg/m)"
        )
        rates = [
            run_episode(sim, path, None, EpisodeConfig(seed=s)).failures_per_km for s in range(5)
        ]
        print(
            f"  odometry-only failure rate: {np.mean(rates):.1f} per km (seeds 0-4: "
            f"{', '.join(f'{r:.1f}' for r in rates)}; std {np.std(rates):.1f}); "
            f"paper {PAPER_ODOMETRY_RATE[name]}"
        )
        if name == "town01":
            print(f"  odometry-only episode speed: {median_rtf(sim, path, None):.0f}x real time")
            print(
                f"  with one 800x600 camera at 2 Hz: "
                f"{median_rtf(sim, path, RenderOnly()):.1f}x real time"
            )
        sim.close()


if __name__ == "__main__":
    main()
