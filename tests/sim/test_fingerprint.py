"""The renderer's fingerprint: the same in every process of a machine, another for another driver."""

import json

import pytest

from tests.conftest import last_line_in_a_process
from vlocbench.sim.fingerprint import render_fingerprint

_PRINT = (
    "import json, dataclasses; from vlocbench.sim.fingerprint import render_fingerprint; "
    "print(json.dumps(dataclasses.asdict(render_fingerprint())))"
)


def _in_a_process(**env):
    return json.loads(last_line_in_a_process(_PRINT, **env))


def test_the_fingerprint_is_the_machines_and_tells_another_driver_apart():
    here = render_fingerprint()
    assert len(here.digest) == 16 and here.gl_renderer and here.backend in ("egl", "osmesa")
    # another process, one rasterizer thread (as a pool worker): the same pixels
    assert _in_a_process(LP_NUM_THREADS="1")["digest"] == here.digest
    if "llvmpipe" not in here.gl_renderer:
        pytest.skip(f"Mesa's softpipe is the other driver tried; this machine draws with {here}")
    # Mesa's other software rasterizer draws the same scene a little differently
    soft = _in_a_process(GALLIUM_DRIVER="softpipe")
    assert soft["gl_renderer"] == "softpipe" and soft["digest"] != here.digest
