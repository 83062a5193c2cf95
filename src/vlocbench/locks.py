"""A folder that one process at a time builds: galleries and maps in the shared cache."""

from __future__ import annotations

import fcntl
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

LOCK_FILE = ".building"

logger = logging.getLogger(__name__)


@contextmanager
def building(folder: Path, what: str) -> Iterator[None]:
    """Hold ``folder`` (created if missing) while building ``what`` in it. Another process that
    builds the same thing (a second run sharing the cache) waits here, then finds it finished,
    instead of writing the same files at the same time."""
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / LOCK_FILE, "a") as lock:  # "a": taking the lock changes nothing in it
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            logger.info(f"another process is building {what} in {folder}; waiting for it")
            fcntl.flock(lock, fcntl.LOCK_EX)
        yield  # the lock goes with the file's closing


@contextmanager
def unless_building(folder: Path) -> Iterator[bool]:
    """Hold ``folder``'s lock if no process is building in it: True while held, False (and not
    held) when one is. For removing a folder without pulling it from under a build."""
    with open(folder / LOCK_FILE, "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        yield True  # the lock goes with the file's closing
