"""vlocbench: is this visual localization method good enough to navigate with?

A car drives a route through a MuJoCo-rendered town with a full navigation stack (planners, PID
control, an EKF fusing wheel odometry with visual localization); between the gallery drive and the
test drive the world changes (light, weather, viewpoint, season, camera, traffic). The benchmark
measures localization recall and navigation failures per km against odometry alone, as Suomela et
al. (WACV 2023) did in CARLA.

Stages live in sub-packages: ``sim`` (towns, rendering, vehicle), ``nav`` (the navigation stack),
``loc`` (galleries, maps, localizers) and ``bench`` (episodes, experiments, results, reports), which
alone composes the others; ``vlocbench.cli`` is the command line. Import them explicitly, e.g.
``from vlocbench.sim import Simulator``; the top level stays import-light.
"""

__version__ = "0.1.0"
