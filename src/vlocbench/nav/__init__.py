"""Navigation stack (pure numerics): planners, control, wheel odometry, EKF, failures, progress.

Imports neither ``sim`` nor ``loc``; the episode loop in ``bench`` wires it to them.
"""

from vlocbench.nav.control import ControllerConfig, Pid, PidGains, VehicleController
from vlocbench.nav.ekf import Ekf, EkfConfig, PoseMeasurement, UpdateOutcome
from vlocbench.nav.failure import Failure, FailureConfig, FailureDetector
from vlocbench.nav.global_planner import GlobalPlanner, LanePoint
from vlocbench.nav.local_planner import LocalPlanner, LocalPlannerConfig, LocalTarget
from vlocbench.nav.odometry import (
    Drift,
    OdometryNoise,
    OdometryReading,
    WheelOdometry,
    dead_reckoning_drift,
    integrate_planar,
)
from vlocbench.nav.path import Projection, WaypointPath
from vlocbench.nav.progress import ProgressConfig, ProgressTracker

__all__ = [
    "ControllerConfig",
    "Drift",
    "Ekf",
    "EkfConfig",
    "Failure",
    "FailureConfig",
    "FailureDetector",
    "GlobalPlanner",
    "LanePoint",
    "LocalPlanner",
    "LocalPlannerConfig",
    "LocalTarget",
    "OdometryNoise",
    "OdometryReading",
    "Pid",
    "PidGains",
    "PoseMeasurement",
    "ProgressConfig",
    "ProgressTracker",
    "Projection",
    "UpdateOutcome",
    "VehicleController",
    "WaypointPath",
    "WheelOdometry",
    "dead_reckoning_drift",
    "integrate_planar",
]
