"""The native libraries' side effects on the process, undone: pycolmap's glog installs a failure
handler for SIGTERM at import (it prints a native stack trace and kills the process, so a
container stop, systemd or a launch system would never reach our clean shutdown), and logs every
warning (Ceres's ``Jacobian matrix is rank deficient`` for each degenerate pose covariance, many
times per run). vlocbench imports pycolmap from here only.

Native log lines: errors only, unless ``VLOCBENCH_NATIVE_LOG`` is set (``vlocbench -v`` sets it,
and worker processes inherit it).
"""

from __future__ import annotations

import os
import signal
import threading

from vlocbench.config import NATIVE_LOG_ENV

_python_sigterm = signal.getsignal(signal.SIGTERM)
import pycolmap  # noqa: E402  (glog's handler replaces the one read above)

if threading.current_thread() is threading.main_thread() and _python_sigterm is not None:
    signal.signal(signal.SIGTERM, _python_sigterm)

_ERRORS_ONLY, _EVERYTHING = 2, 0  # glog's minimum levels: ERROR, INFO
__all__ = ["pycolmap", "quiet_pycolmap"]


def quiet_pycolmap() -> None:
    """Set pycolmap's minimum log level from ``VLOCBENCH_NATIVE_LOG``."""
    verbose = os.environ.get(NATIVE_LOG_ENV, "") not in ("", "0")
    pycolmap.logging.minloglevel = _EVERYTHING if verbose else _ERRORS_ONLY
