"""The native libraries' own log lines (pycolmap's glog: COLMAP, Ceres): errors only, unless
``VLOCBENCH_NATIVE_LOG`` is set (``vlocbench -v`` sets it, and worker processes inherit it).

Without this, a localization prints Ceres's ``Jacobian matrix is rank deficient`` warning whenever
a pose's covariance is degenerate, many times per run, straight to stderr."""

from __future__ import annotations

import os

from vlocbench.config import NATIVE_LOG_ENV

_ERRORS_ONLY, _EVERYTHING = 2, 0  # glog's minimum levels: ERROR, INFO


def quiet_pycolmap() -> None:
    """Set pycolmap's minimum log level from ``VLOCBENCH_NATIVE_LOG``."""
    import pycolmap

    verbose = os.environ.get(NATIVE_LOG_ENV, "") not in ("", "0")
    pycolmap.logging.minloglevel = _EVERYTHING if verbose else _ERRORS_ONLY
