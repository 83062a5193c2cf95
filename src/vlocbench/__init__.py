"""vlocbench: is this visual localization method good enough to navigate with?

Stages live in sub-packages (``sim``, later ``nav``, ``loc``, ``bench``); import them explicitly,
e.g. ``from vlocbench.sim import Simulator``. The top level stays import-light.
"""

__version__ = "0.1.0"
