"""The embedded town simulator: procedural towns, MuJoCo rendering, conditions, a vehicle.

Importing this package selects the headless GL backend (``MUJOCO_GL``, EGL by default) before MuJoCo
is imported; see ``backend.py``.
"""

from vlocbench.sim.backend import select_backend

select_backend()

from vlocbench.interfaces import Control  # noqa: E402
from vlocbench.sim.camera import Camera, Extrinsics, Intrinsics, gallery_camera  # noqa: E402
from vlocbench.sim.conditions import (  # noqa: E402
    Conditions,
    Exposure,
    Headlights,
    Illumination,
    StreetLights,
    Traffic,
    Viewpoint,
    Weather,
)
from vlocbench.sim.simulator import Frame, Simulator, StepResult  # noqa: E402
from vlocbench.sim.town import Town, TownSpec, builtin_town_names, generate_town, load_town_spec  # noqa: E402
from vlocbench.sim.vehicle import VehicleParams, VehicleState  # noqa: E402

__all__ = [
    "Camera",
    "Conditions",
    "Control",
    "Exposure",
    "Extrinsics",
    "Frame",
    "Headlights",
    "Illumination",
    "Intrinsics",
    "Simulator",
    "StepResult",
    "StreetLights",
    "Town",
    "TownSpec",
    "Traffic",
    "VehicleParams",
    "VehicleState",
    "Viewpoint",
    "Weather",
    "builtin_town_names",
    "gallery_camera",
    "generate_town",
    "load_town_spec",
]
