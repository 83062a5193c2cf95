"""The native libraries' log: errors only by default, everything with VLOCBENCH_NATIVE_LOG."""

import os
import subprocess
import sys

import pytest

from vlocbench.config import NATIVE_LOG_ENV

PROBE = """
import pycolmap
from vlocbench.loc.native import quiet_pycolmap
pycolmap.logging.minloglevel = 0
quiet_pycolmap()
print(pycolmap.logging.minloglevel)
pycolmap.logging.warning("a native warning")  # as Ceres's rank-deficiency lines reach glog
"""


@pytest.mark.parametrize(("env", "level", "shown"), [("", 2, False), ("1", 0, True)])
def test_native_warnings_show_only_when_asked(env, level, shown):
    run = subprocess.run(
        [sys.executable, "-c", PROBE],
        env={**os.environ, NATIVE_LOG_ENV: env},
        capture_output=True,
        text=True,
        check=True,
    )
    assert run.stdout.split() == [str(level)]
    assert ("a native warning" in run.stderr) == shown
