"""The embedded simulator: a town scene, the ego vehicle, traffic, collisions and cameras.

Synchronous: each ``step`` advances the world by ``dt_s`` (0.05 s by default). Rendering is lazy (no
GL context is made until the first ``render``), so driving without cameras costs no GPU/CPU GL time.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from vlocbench.config import require
from vlocbench.interfaces import Array, Control
from vlocbench.sim.camera import Camera
from vlocbench.sim.collision import CollisionEvent, touching
from vlocbench.sim.conditions import Conditions
from vlocbench.sim.renderer import Renderer
from vlocbench.sim.scene import SceneOptions, TownScene, build_scene
from vlocbench.sim.town import Town
from vlocbench.sim.traffic import TrafficModel
from vlocbench.sim.vehicle import VehicleParams, VehicleState, at_rest, step_vehicle


@dataclass(frozen=True)
class Frame:
    """One camera image with its exact ground truth. ``image``: (H, W, 3) uint8 RGB."""

    camera: Camera
    image: NDArray[np.uint8]
    world_from_cam: Array
    time_s: float


@dataclass(frozen=True)
class StepResult:
    state: VehicleState
    collisions: tuple[CollisionEvent, ...] = field(default=())


class Simulator:
    """Drive a car through ``town`` under ``conditions``; render its cameras on demand.

    Holds an OpenGL context once it has rendered: ``close()`` it, or use it as a context manager.
    """

    def __init__(
        self,
        town: Town,
        conditions: Conditions | None = None,
        vehicle: VehicleParams | None = None,
        dt_s: float = 0.05,
    ) -> None:
        require(0 < dt_s <= 0.5, "dt_s", f"must be in (0, 0.5] s, got {dt_s}")
        self.town = town
        self.conditions = conditions or Conditions()
        self.params = vehicle or VehicleParams()
        self.dt_s = dt_s
        traffic = self.conditions.traffic
        self.scene: TownScene = build_scene(
            town, SceneOptions(max_cars=traffic.cars, max_pedestrians=traffic.pedestrians)
        )
        route = town.route
        x0, y0 = (float(v) for v in route.waypoints_xy[0])
        self.state = VehicleState(x0, y0, float(route.yaw_rad[0]))
        self.traffic = TrafficModel(town, traffic, avoid_xy=route.waypoints_xy[0])
        self._renderer: Renderer | None = None
        self._touching: set[str] = set()
        self._placed()

    @property
    def renderer(self) -> Renderer:
        if self._renderer is None:
            self._renderer = Renderer(self.scene, self.conditions)
        return self._renderer

    def set_conditions(self, conditions: Conditions) -> None:
        """Change appearance conditions (traffic counts are fixed when the scene is built)."""
        if conditions.traffic != self.conditions.traffic:
            require(
                conditions.traffic.cars <= self.scene.options.max_cars
                and conditions.traffic.pedestrians <= self.scene.options.max_pedestrians,
                "traffic",
                "more cars or pedestrians than the scene was built with; make a new Simulator",
            )
            self.traffic = TrafficModel(self.town, conditions.traffic, avoid_xy=self.position_xy)
        self.conditions = conditions
        if self._renderer is not None:
            self._renderer.apply(conditions)

    def set_vehicle(self, vehicle: VehicleParams) -> None:
        """Drive the car with other parameters from the next step on."""
        self.params = vehicle

    @property
    def position_xy(self) -> Array:
        return np.array([self.state.x_m, self.state.y_m])

    def _sync(self) -> None:
        sc = self.scene
        sc.set_free_pose(sc.ego_qpos_adr, self.state.x_m, self.state.y_m, self.state.yaw_rad)
        for adr, (x, y, yaw) in zip(sc.car_qpos_adr, self.traffic.car_poses()):
            sc.set_free_pose(adr, x, y, yaw)
        for adr, (x, y, yaw) in zip(sc.pedestrian_qpos_adr, self.traffic.pedestrian_poses()):
            sc.set_free_pose(adr, x, y, yaw)
        sc.forward()

    def step(self, control: Control) -> StepResult:
        """Advance by ``dt_s``; report collisions that started during this step."""
        self.state = step_vehicle(self.state, control, self.params, self.dt_s)
        if self.traffic.cars or self.traffic.pedestrians:
            self.traffic.step(self.dt_s, self.position_xy)
        self._sync()
        now = touching(self.scene)
        events = tuple(
            CollisionEvent(self.state.time_s, x, y, category, label)
            for label, (category, x, y) in sorted(now.items())
            if label not in self._touching
        )
        self._touching = set(now)
        return StepResult(self.state, events)

    def reset(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState:
        """Start an episode: the car at rest at a pose, the clock at 0, traffic at its seeded start.

        After a reset the simulation depends only on the controls that follow, not on its past.
        """
        self.state = VehicleState(x_m, y_m, yaw_rad)
        self.traffic = TrafficModel(self.town, self.conditions.traffic, avoid_xy=self.position_xy)
        return self._placed()

    def teleport(self, x_m: float, y_m: float, yaw_rad: float) -> VehicleState:
        """Place the car at rest at a new pose (re-initialization); contacts there are not events."""
        self.state = at_rest(self.state, x_m, y_m, yaw_rad)
        return self._placed()

    def _placed(self) -> VehicleState:
        """Sync the scene to a car put down by hand: what it touches there is not an event."""
        self._sync()
        self._touching = set(touching(self.scene))
        return self.state

    def render(self, cameras: Sequence[Camera], frame_id: int | None = None) -> list[Frame]:
        """Render every camera of the rig at the current state (viewpoint offsets applied)."""
        vp = self.conditions.viewpoint
        frame_id = round(self.state.time_s / self.dt_s) if frame_id is None else frame_id
        world_from_vehicle = self.state.world_from_vehicle()
        frames = []
        for k, cam in enumerate(cameras):
            cam = cam.offset(vp.dz_m, vp.pitch_down_deg) if (vp.dz_m or vp.pitch_down_deg) else cam
            pose = cam.world_from_cam(world_from_vehicle)
            i = cam.intrinsics
            image = self.renderer.render(
                pose, i.width, i.height, i.fov_deg, frame_id * 16 + k, antialias=cam.antialias
            )
            frames.append(Frame(cam, image, pose, self.state.time_s))
        return frames

    def __enter__(self) -> Simulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
