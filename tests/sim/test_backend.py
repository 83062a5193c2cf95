import os
import subprocess
import sys
from pathlib import Path

import pytest

# a render in a process that imported mujoco first, with MUJOCO_GL unset
SCRIPT = """
import mujoco
from vlocbench.errors import RenderBackendError
from vlocbench.sim import Simulator, gallery_camera
from vlocbench.sim.town import generate_town
from tests.conftest import small_spec
try:
    Simulator(generate_town(small_spec())).render([gallery_camera()])
except RenderBackendError as e:
    print(e)
else:
    print("rendered")
"""


def test_importing_mujoco_first_is_named_as_the_cause():
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT],
        env=env,
        cwd=Path(__file__).parents[2],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    if "rendered" in out:  # a MuJoCo that picks a headless backend by itself
        pytest.skip("this MuJoCo renders headless without MUJOCO_GL")
    assert "mujoco was imported before vlocbench.sim" in out and "MUJOCO_GL=egl" in out
