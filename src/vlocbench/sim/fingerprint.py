"""What this machine's renderer draws: a digest of a fixed scene's pixels, and the driver's name.

One machine renders the same scene and pose to the same pixels, every time. Another OpenGL driver
need not: softpipe draws a street of the test town a level or so off llvmpipe's at 44 % of an
800x600 frame's pixels (both Mesa 22.3), a GPU's driver differs again, and a closed-loop drive
carries such a difference on into other answers, another path and other failures. A result that
records this digest says which renderer drew its images; two results with the same digest were
drawn alike.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass

import numpy as np

from vlocbench.sim.camera import Camera, Extrinsics, Intrinsics
from vlocbench.sim.conditions import Conditions, Illumination
from vlocbench.sim.simulator import Simulator
from vlocbench.sim.town import RouteSpec, TownSpec, generate_town

# a 2x2-block town and its route: built and drawn in about a second
_SPEC = TownSpec(
    name="fingerprint",
    seed=3,
    block_widths_m=(50.0, 50.0),
    block_depths_m=(50.0, 50.0),
    border_m=25.0,
    route=RouteSpec(nodes=((0, 0), (2, 0), (2, 2)), start_offset_m=15.0, end_offset_m=15.0),
)
# the default camera's sampling, small: the same shaders as a drive's frame
_CAMERA = Camera("right", Intrinsics(160, 120, 90.0), Extrinsics())
# noon, and night with the town's lights: the sun's shading and the lamps' and windows' paths
_CONDITIONS = (Conditions(), Conditions(illumination=Illumination(k=10)))


@dataclass(frozen=True)
class RenderFingerprint:
    """The digest of the fixed scene's pixels (16 hex digits) and what drew them."""

    digest: str
    backend: str  # MUJOCO_GL: egl or osmesa
    gl_renderer: str  # the driver, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
    gl_version: str


@functools.cache
def render_fingerprint() -> RenderFingerprint:
    """This process's fingerprint, made once (a small town built and drawn twice)."""
    from OpenGL import GL

    digest = hashlib.sha256()
    with Simulator(generate_town(_SPEC)) as sim:
        for conditions in _CONDITIONS:
            sim.set_conditions(conditions)
            image = np.ascontiguousarray(sim.render([_CAMERA], frame_id=0)[0].image)
            digest.update(image.tobytes())
        # the context that drew the frames is current: ask it which driver it is
        renderer, version = (
            GL.glGetString(name).decode(errors="replace")
            for name in (GL.GL_RENDERER, GL.GL_VERSION)
        )
        backend = sim.renderer.backend
    return RenderFingerprint(digest.hexdigest()[:16], backend, renderer, version)
