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


def test_without_a_terminal_a_line_every_period_and_at_the_end(caplog):
    caplog.set_level(logging.INFO, logger="vlocbench.progress")
    log = Progress("episodes", 10, "episode", stream=io.StringIO(), period_s=3600)
    for done in range(1, 11):
        log.update_to(done, "ok 3")
    assert [r.getMessage() for r in caplog.records] == ["episodes: 10/10 episodes (100 %); ok 3"]
    caplog.clear()
    every = Progress("maps", 2, "map", stream=io.StringIO(), period_s=0)
    every.update_to(1)
    every.update_to(2)
    assert [r.getMessage() for r in caplog.records] == [
        "maps: 1/2 maps (50 %)",
        "maps: 2/2 maps (100 %)",
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
