"""Simulator performance: render time, vehicle step + collision query, town scene build.

Prints medians of several runs after a warm-up. Targets (issues 2 and 14, this 2-core CPU):
800x600 render <= 40 ms by day, vehicle step + collision <= 1 ms, town scene build <= 5 s. Renders
are timed with the default camera (one sample per pixel) and, by day and at night, with
``Camera(antialias=True)`` (4x multisampling); at night k = 8 and 10 the street lamps and lit windows are on (the
default ``StreetLights``); ``shadows``: the sun casts shadows (``Conditions(shadows=True)``);
``rain+puddles``: the paper's rain (1.0, deposits following it), ``rain 0.7``: streaks and wet
materials without puddles.
"""

from __future__ import annotations

import dataclasses
import statistics
import time

import numpy as np

from vlocbench.sim import (
    Conditions,
    Control,
    Illumination,
    Simulator,
    StreetLights,
    Weather,
    gallery_camera,
)
from vlocbench.sim.scene import build_scene
from vlocbench.sim.town import generate_town, load_town_spec


def timed(fn, repeat: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    for name in ("town01", "town10"):
        spec = load_town_spec(name)
        build_s = timed(lambda: build_scene(generate_town(spec)), 3)  # noqa: B023
        town = generate_town(spec)
        sim = Simulator(town)
        step_ms = 1000 * timed(lambda: sim.step(Control(throttle=0.2)), 2000)  # noqa: B023
        default = gallery_camera()
        aa = dataclasses.replace(default, antialias=True)
        unlit = StreetLights("off")
        waypoints = np.linspace(5, len(town.route.waypoints_xy) - 5, 20).astype(int)
        print(
            f"{name}: scene build (generate + compile) {build_s:.2f} s; step + collision {step_ms:.3f} ms"
        )
        for label, cond, camera in (
            ("day", Conditions(), default),
            ("night k=8", Conditions(illumination=Illumination(k=8)), default),
            ("k=10", Conditions(illumination=Illumination(k=10)), default),
            (
                "k=10, unlit",
                Conditions(illumination=Illumination(k=10), street_lights=unlit),
                default,
            ),
            ("day, shadows", Conditions(shadows=True), default),
            ("k=4, shadows", Conditions(illumination=Illumination(k=4), shadows=True), default),
            ("fog 30 m", Conditions(weather=Weather(fog_visual_range_m=30)), default),
            ("rain 0.7", Conditions(weather=Weather(rain=0.7, deposits=0.0)), default),
            ("rain+puddles", Conditions(weather=Weather(rain=1.0)), default),
            ("rain+fog 60", Conditions(weather=Weather(rain=1.0, fog_visual_range_m=60)), default),
            ("day, 4x AA", Conditions(), aa),
            ("k=8, 4x AA", Conditions(illumination=Illumination(k=8)), aa),
        ):
            sim.set_conditions(cond)
            frames = []
            for idx in waypoints:
                x, y = town.route.waypoints_xy[idx]
                sim.teleport(float(x), float(y), float(town.route.yaw_rad[idx]))
                frames.append(1000 * timed(lambda: sim.render([camera]), 3))  # noqa: B023
            print(
                f"  render 800x600 {label:12s}: median {statistics.median(frames):5.1f} ms (20 places x 3)"
            )
        sim.close()


if __name__ == "__main__":
    main()
