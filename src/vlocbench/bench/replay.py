"""An episode's query images, rendered again from its stored config and true poses.

Episodes store poses, not images (a town01 drive would be about a gigabyte of them). The images
come back exactly as the episode saw them for the scene, the light, the weather and the sensor
noise (seeded by the frame number); moving traffic is not replayed, the town is empty.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from vlocbench.bench.towns import town_named
from vlocbench.config import from_dict
from vlocbench.interfaces import Image
from vlocbench.sim import Frame, Simulator
from vlocbench.sim.camera import Camera
from vlocbench.sim.conditions import Conditions


def episode_camera(config: dict[str, Any]) -> Camera:
    """The first query camera of a stored episode ``config``, the viewpoint's change applied."""
    setup = config["setup"]
    vp = from_dict(Conditions, setup["conditions"]).viewpoint
    return from_dict(Camera, setup["cameras"][0]).offset(vp.dz_m, vp.pitch_down_deg)


class QueryRenderer:
    """The episode's first query camera rendered at a true pose; a context manager."""

    def __init__(self, config: dict[str, Any]) -> None:
        conditions = from_dict(Conditions, config["setup"]["conditions"])
        # the viewpoint's change is in the camera already, not to be applied twice
        static = replace(
            conditions, viewpoint=replace(conditions.viewpoint, dz_m=0.0, pitch_down_deg=0.0)
        )
        self.camera = episode_camera(config)
        self.sim = Simulator(town_named(config["town"]), static)

    def frame(self, x_m: float, y_m: float, yaw_rad: float, time_s: float) -> Frame:
        """The camera's frame with the car at (x, y, yaw) and the episode's noise at ``time_s``:
        its image and the camera's true pose."""
        self.sim.teleport(float(x_m), float(y_m), float(yaw_rad))
        return self.sim.render([self.camera], frame_id=round(time_s / self.sim.dt_s))[0]

    def image(self, x_m: float, y_m: float, yaw_rad: float, time_s: float) -> Image:
        """(H, W, 3) uint8 RGB of :meth:`frame`."""
        return self.frame(x_m, y_m, yaw_rad, time_s).image

    def close(self) -> None:
        self.sim.close()

    def __enter__(self) -> QueryRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
