"""Progress: bars in the right units on a terminal, a line every few seconds elsewhere."""

import io
import logging

from vlocbench.bench.preparation import StageBars
from vlocbench.bench.progress import Progress, unit_of


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_stage_counts_in_its_own_unit():
    assert [
        unit_of(s)
        for s in (
            "town10 gallery",
            "town10 sift features",
            "town10 sift matches",
            "maps",
            "episodes",
        )
    ] == ["image", "image", "pair", "map", "episode"]
    screen = Terminal()
    bar = Progress("town10 sift matches", 40, "pair", stream=screen)
    bar.update_to(40)
    bar.close()
    assert "40/40" in screen.getvalue() and "pair/s" in screen.getvalue()


class Clock:
    """Seconds that pass only when a test says so."""

    def __init__(self):
        self.s = 1000.0

    def __call__(self):
        return self.s


def test_without_a_terminal_a_line_every_period_and_at_the_end(caplog):
    caplog.set_level(logging.INFO, logger="vlocbench.progress")
    clock = Clock()
    log = Progress("episodes", 10, "episode", stream=io.StringIO(), period_s=3600, clock=clock)
    for done in range(1, 11):
        clock.s += 30
        log.update_to(done, "ok 3")
    assert [r.getMessage() for r in caplog.records] == [
        "episodes: 10/10 episodes (100 %) in 5 min; ok 3"
    ]
    caplog.clear()
    clock = Clock()
    every = Progress("maps", 4, "map", stream=io.StringIO(), period_s=0, clock=clock)
    every.update_to(0)
    clock.s += 1200
    every.update_to(1)
    clock.s += 2 * 3600
    every.update_to(4)
    # the time left from the rate so far: 3 maps at 20 min each
    assert [r.getMessage() for r in caplog.records] == [
        "maps: 0/4 maps (0 %), 0 s so far",
        "maps: 1/4 maps (25 %), 20 min so far, about 60 min left",
        "maps: 4/4 maps (100 %) in 2.3 h",
    ]


def test_a_finished_stage_is_closed_at_once(caplog):
    caplog.set_level(logging.INFO, logger="vlocbench.progress")
    bars = StageBars(enabled=True)
    bars("town10 gallery", 5, 5)
    assert not bars.bars  # closed as it finished: nothing is drawn again later
    bars("town10 sift matches", 1, 3)
    assert list(bars.bars) == ["town10 sift matches"]
    bars.close()
    assert "town10 gallery: 5/5 images (100 %)" in caplog.text
