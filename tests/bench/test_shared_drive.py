import dataclasses

import numpy as np
import pytest

from tests.conftest import CAMERA
from vlocbench.bench import EpisodeConfig, LatencyConfig, run_episode
from vlocbench.bench.shared_drive import can_share, run_shared_drive
from vlocbench.bench.visual import VisualLocalizer
from vlocbench.config import to_dict
from vlocbench.loc.features import DogSiftExtractor
from vlocbench.loc.localizer import LocalizerConfig
from vlocbench.sim import Simulator

RECALL = EpisodeConfig(mode="ground_truth")


class Counting(Simulator):
    """A real simulator that counts its renders."""

    renders = 0

    def render(self, cameras, frame_id=None):
        self.renders += 1
        return super().render(cameras, frame_id)


class Scribbling(VisualLocalizer):
    """Blacks out its input after localizing; raises at query ``fail_at`` (1-based) if set."""

    def __init__(self, *args, fail_at=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.fail_at, self.seen = fail_at, 0

    def reset(self, seed):
        self.seen = 0

    def localize(self, query):
        self.seen += 1
        if self.seen == self.fail_at:
            raise RuntimeError("a localizer's bug")
        estimate = super().localize(query)
        for frame in query.frames:
            frame.image[:] = 0
        return estimate


def _comparable(result):
    """An episode's result without its wall and compute times (the stages' names kept)."""
    d = to_dict(dataclasses.replace(result, wall_time_s=0.0))
    for rec in d["localizations"]:
        rec["compute_time_s"] = 0.0
        rec["stage_s"] = sorted(rec["stage_s"])
    return d


@pytest.fixture(scope="module")
def short(stretch):
    return stretch.head(25.0)


@pytest.fixture(scope="module")
def methods(sift_map):
    gated = LocalizerConfig(min_inliers=40)  # fails some queries the plain one answers
    return lambda **kw: [
        VisualLocalizer(sift_map[0], (CAMERA,), name="sift"),
        Scribbling(sift_map[0], (CAMERA,), gated, name="sift-gated", **kw),
        VisualLocalizer(sift_map[0], (CAMERA,), LocalizerConfig(top_k=2), name="sift-top2"),
    ]


@pytest.fixture(scope="module")
def alone(small_town, short, methods):
    """Each method's recall drive on its own, and the renders one drive takes."""
    with Counting(small_town) as sim:
        results = [run_episode(sim, short, loc, RECALL) for loc in methods()]
    return results, sim.renders // len(results)


def test_recall_drives_of_several_methods_share_one_drive(
    small_town, short, methods, alone, monkeypatch
):
    solo, renders = alone
    extract, extractions = DogSiftExtractor.extract, []

    def counted(self, image):
        extractions.append(1)
        return extract(self, image)

    monkeypatch.setattr(DogSiftExtractor, "extract", counted)
    with Counting(small_town) as sim:
        shared = run_shared_drive(sim, short, methods(), RECALL)
    # each image rendered and its SIFT extracted once for all three, and every result the one it
    # gives alone, although a localizer blacks out the images it is given
    assert sim.renders == len(extractions) == renders >= 10
    for result, own in zip(shared, solo, strict=True):
        assert not isinstance(result, Exception)
        np.testing.assert_equal(_comparable(result), _comparable(own))
    answered = [sum(r.success for r in x.localizations) for x in solo]
    assert answered[0] > answered[1] > 0  # the methods differ: the comparison can fail
    # the lead's time holds the simulator's and the renders; each has its own
    assert all(r.wall_time_s > 0 for r in shared)


def test_a_method_that_raises_leaves_the_drive_to_the_others(small_town, short, methods, alone):
    solo, _ = alone
    with Simulator(small_town) as sim:
        follower_fails = run_shared_drive(sim, short, methods(fail_at=5), RECALL)
        lead_fails = run_shared_drive(sim, short, methods(fail_at=5)[1:], RECALL)
    assert isinstance(follower_fails[1], RuntimeError)
    assert isinstance(lead_fails[0], RuntimeError)  # the others drove again without it
    for result, own in ((follower_fails[0], solo[0]), (follower_fails[2], solo[2])):
        np.testing.assert_equal(_comparable(result), _comparable(own))
    np.testing.assert_equal(_comparable(lead_fails[1]), _comparable(solo[2]))


def test_only_drives_that_no_localizer_steers_are_shared(small_town, short, sift_map):
    assert can_share(RECALL) and can_share(
        dataclasses.replace(RECALL, latency=LatencyConfig("none"))
    )
    assert not can_share(EpisodeConfig())  # navigate: each localizer steers its own car
    # a measured latency moves each method's localization ticks
    assert not can_share(dataclasses.replace(RECALL, latency=LatencyConfig("measured")))
    loc = VisualLocalizer(sift_map[0], (CAMERA,))
    with Simulator(small_town) as sim, pytest.raises(ValueError, match="ground_truth"):
        run_shared_drive(sim, short, [loc, loc], EpisodeConfig())
