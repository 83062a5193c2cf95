"""Progress of the long stages (galleries, features, matches, maps, episodes): a tqdm bar on a
terminal; where nobody watches one (output to a file, CI, a cluster job), a log line every
``period_s`` seconds and one at the end, instead of thousands of carriage-return updates, each with
the time so far and, from the rate so far, the time left."""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable
from typing import Any, TextIO

logger = logging.getLogger("vlocbench.progress")

# a stage's unit from the last word of its name ("town10 sift matches" counts pairs)
UNITS = {
    "gallery": "image",
    "features": "image",
    "matches": "pair",
    "galleries": "gallery",
    "maps": "map",
    "episodes": "episode",
}
PERIOD_S = 10.0


def unit_of(stage: str) -> str:
    return UNITS.get(stage.split()[-1], "item")


def duration(seconds: float) -> str:
    """``seconds`` as a person reads a stage's length: 45 s, 12 min, 2.5 h."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 90 * 60:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


class Progress:
    """``total`` steps of ``desc`` counted in ``unit``s; :meth:`update_to` as they finish."""

    def __init__(
        self,
        desc: str,
        total: int,
        unit: str,
        stream: TextIO | None = None,
        period_s: float = PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.desc, self.total, self.unit, self.period_s = desc, total, unit, period_s
        self.clock = clock  # seconds
        self.done, self._start_s = 0, clock()
        self._logged_s = self._start_s
        stream = stream or sys.stderr
        self._bar: Any = None
        if stream.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True, file=stream)

    def update_to(self, done: int, postfix: str = "") -> None:
        self.done = done
        if self._bar is not None:
            if postfix:
                self._bar.set_postfix_str(postfix, refresh=False)
            self._bar.update(done - self._bar.n)
        elif done >= self.total or self.clock() - self._logged_s >= self.period_s:
            self._logged_s = self.clock()
            share = 100 * done / self.total if self.total else 100.0
            spent_s = self._logged_s - self._start_s
            if done >= self.total:
                timing = f" in {duration(spent_s)}"
            elif done > 0:
                left_s = spent_s * (self.total - done) / done  # at the rate so far
                timing = f", {duration(spent_s)} so far, about {duration(left_s)} left"
            else:
                timing = f", {duration(spent_s)} so far"
            tail = f"; {postfix}" if postfix else ""
            logger.info(
                f"{self.desc}: {done}/{self.total} {self.unit}s ({share:.0f} %){timing}{tail}"
            )

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
