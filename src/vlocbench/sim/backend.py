"""Choosing the headless OpenGL backend before MuJoCo is imported.

MuJoCo reads ``MUJOCO_GL`` when it is imported. We default to EGL (Mesa's llvmpipe on a CPU), fall
back to OSMesa when only that is installed, and name the Debian packages when neither is.
"""

from __future__ import annotations

import ctypes.util
import os
import sys

from vlocbench.errors import RenderBackendError

DEBIAN_PACKAGES = {
    "egl": "libegl1 libgl1 libgl1-mesa-dri libegl-mesa0 libgles2",
    "osmesa": "libosmesa6",
}
_LIBRARIES = {"egl": ("EGL", "GL"), "osmesa": ("OSMesa",)}
# MuJoCo was imported before a backend was chosen: it read no MUJOCO_GL and has no headless context
_too_late = False


def _available(backend: str) -> bool:
    return all(ctypes.util.find_library(lib) for lib in _LIBRARIES[backend])


def select_backend() -> str:
    """Set ``MUJOCO_GL`` (and PyOpenGL's platform) if unset; return the backend in use."""
    global _too_late
    backend = os.environ.get("MUJOCO_GL")
    if backend is None:
        _too_late = "mujoco" in sys.modules
        backend = "egl" if _available("egl") or not _available("osmesa") else "osmesa"
        os.environ["MUJOCO_GL"] = backend
    if backend in _LIBRARIES:
        os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    return backend


def missing_libraries_error(backend: str, cause: BaseException) -> RenderBackendError:
    if _too_late:
        return RenderBackendError(
            f"cannot start the headless OpenGL backend ({cause}): mujoco was imported before "
            "vlocbench.sim, with MUJOCO_GL unset, so MuJoCo chose no headless backend. Import "
            f"vlocbench.sim before mujoco, or set MUJOCO_GL={backend} in the environment"
        )
    packages = DEBIAN_PACKAGES.get(backend, DEBIAN_PACKAGES["egl"])
    return RenderBackendError(
        f"cannot start the headless OpenGL backend MUJOCO_GL={backend!r} ({cause}). "
        f"On Debian/Ubuntu install its libraries: apt-get install -y {packages} "
        f"(or set MUJOCO_GL=osmesa with: apt-get install -y {DEBIAN_PACKAGES['osmesa']})"
    )
