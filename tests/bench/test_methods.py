from collections.abc import Sequence

import numpy as np
import pytest
import yaml

from tests.conftest import small_spec
from vlocbench.bench import LocalizationQuery, PoseEstimate
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.methods import MethodContext, MethodSpec, build_localizer
from vlocbench.bench.runner import run_experiment
from vlocbench.bench.store import ResultStore
from vlocbench.config import to_dict
from vlocbench.errors import ConfigError
from vlocbench.sim import Camera


class ShiftedTruth:
    """A whole localizer as a user writes one: the true pose moved ``offset_m`` to the left."""

    uses_ground_truth = True

    def __init__(self, context: MethodContext, offset_m: float = 0.0) -> None:
        self.name, self.offset_m, self.resets = context.name, offset_m, 0

    @property
    def cameras(self) -> Sequence[Camera]:
        return ()  # it looks at nothing: nothing is rendered

    def reset(self, seed: int) -> None:
        self.resets += 1

    def localize(self, query: LocalizationQuery) -> PoseEstimate:
        assert query.true_world_from_vehicle is not None
        pose = query.true_world_from_vehicle.copy()
        pose[:3, 3] += pose[:3, 1] * self.offset_m  # the vehicle's y axis: its left
        return PoseEstimate(True, pose, np.diag([0.01, 0.01, 0.001]))

    def close(self) -> None:
        pass


class NoLocalize:
    def __init__(self, context: MethodContext) -> None:
        pass

    def reset(self, seed: int) -> None:
        pass


PLUGIN = f"{__name__}:ShiftedTruth"


def _experiment(root, methods):
    (root / "small.yaml").write_text(yaml.safe_dump(to_dict(small_spec())))
    return load_experiment(
        {
            "name": "plugins",
            "towns": [str(root / "small.yaml")],
            "route_length_m": 60,
            "methods": methods,
            "recall": False,
            "baseline": False,
            "repetitions": 1,
            "output": str(root / "out"),
            "cache": str(root / "cache"),
        }
    )


def test_a_whole_localizer_from_the_tests_drives_an_episode_through_the_runner(tmp_path):
    methods = [
        {"name": "mine", "kind": PLUGIN, "args": {"offset_m": 0.5}},
        {"name": "truth", "kind": "oracle"},  # the oracle, reachable from an experiment
    ]
    plan = _experiment(tmp_path, methods)
    summary = run_experiment(plan, progress=False)
    assert (summary.finished, summary.errors) == (2, 0)
    with ResultStore(tmp_path / "out", "plugins") as store:
        rows = {r.method: r for r in store.rows()}
    assert rows.keys() == {"mine", "truth"}
    assert not (tmp_path / "cache").exists()  # neither needs a gallery or a map
    mine, truth = rows["mine"].metrics, rows["truth"].metrics
    assert mine.failures == truth.failures == 0 and mine.completed
    # the EKF follows the answers: half a metre off to the side, against none for the truth
    assert truth.tracking_error_mean_m < 0.1 < 0.3 < mine.tracking_error_mean_m < 0.7
    # keyed by path and arguments: other arguments are other episodes
    other = _experiment(tmp_path, [{"name": "mine", "kind": PLUGIN, "args": {"offset_m": 1.0}}])
    assert {t.key for t in other.tasks()}.isdisjoint(t.key for t in plan.tasks())


def test_a_plugin_is_built_with_its_context_and_arguments():
    context = MethodContext("mine", ())
    localizer = build_localizer(MethodSpec("mine", kind=PLUGIN, args={"offset_m": 2.0}), context)
    assert isinstance(localizer, ShiftedTruth) and localizer.offset_m == 2.0
    assert localizer.name == "mine"


@pytest.mark.parametrize(
    ("method", "message"),
    [
        ({"kind": "tests.bench.no_such_module:X"}, r"methods\.m\.kind: cannot import"),
        ({"kind": f"{__name__}:Missing"}, f"{__name__} has no Missing"),
        ({"kind": f"{__name__}:PLUGIN"}, "is not a class"),
        ({"kind": f"{__name__}:NoLocalize"}, "lacks localize, close, cameras of the Localizer"),
        ({"kind": PLUGIN, "args": {"offset": 1}}, r"methods\.m\.args: .*offset"),
    ],
)
def test_a_plugin_that_cannot_be_built_stops_the_run_before_any_work(tmp_path, method, message):
    plan = _experiment(tmp_path, [{"name": "m", **method}])
    with pytest.raises(ConfigError, match=message):
        run_experiment(plan, progress=False)
    assert not (tmp_path / "out").exists()


def test_kinds_are_checked_as_the_file_is_read():
    with pytest.raises(ConfigError, match=r"unknown methods\.m\.kind 'orcale'.*map, oracle, ros"):
        MethodSpec("m", kind="orcale")
    with pytest.raises(ConfigError, match=r"methods\.m\.args.*position_sigma_m: must be >= 0"):
        MethodSpec("m", kind="oracle", args={"position_sigma_m": -1})
    with pytest.raises(ConfigError, match="the map kind's settings go under localizer"):
        MethodSpec("sift", args={"top_k": 3})
    with pytest.raises(ConfigError, match="kind oracle takes no features"):
        MethodSpec("m", kind="oracle", features="sift", matcher="nn-ratio", retrieval="vlad")
