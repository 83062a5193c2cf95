"""The accuracy navigation needs: an oracle swept in a real run, a real method placed beside it."""

import numpy as np
import pytest
import yaml

from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.requirements import (
    RAYLEIGH_MEDIAN,
    measured_accuracy,
    oracle_at,
    oracle_sweeps,
)
from vlocbench.errors import ConfigError, UnknownNameError


def test_a_gaussian_oracle_is_placed_at_its_own_sigma():
    rng = np.random.default_rng(0)
    xy = rng.normal(0.0, 0.8, (4000, 2))
    err = np.hypot(xy[:, 0], xy[:, 1])
    locs = {"success": [True] * 4000 + [False] * 1000, "position_error_m": [*err, *[np.nan] * 1000]}
    acc = measured_accuracy(locs)
    assert acc.equivalent_sigma_m == pytest.approx(0.8, rel=0.03)
    assert acc.answer_rate == pytest.approx(0.8) and acc.far_share == 0.0
    assert pytest.approx(1.1774, abs=1e-4) == RAYLEIGH_MEDIAN
    assert oracle_at([0, 1, 2], [0, 4, 10], 1.5) == 7.0
    assert np.isnan(oracle_at([0, 1, 2], [0, 4, 10], 3.0))


def test_method_fields_sweep_as_setups_and_bad_ones_are_named():
    plan = load_experiment("experiments/requirements.yaml")
    assert len(plan.setups) == 6
    sift = {t.key for t in plan.tasks() if t.method_name == "sift"}
    assert len(sift) == 2 * (1 + 3)  # the same in every setup: run once
    oracle = [t for t in plan.tasks() if t.method_name == "oracle" and t.kind == "recall"]
    assert sorted({t.method.args["position_sigma_m"] for t in oracle}) == [0, 0.25, 0.5, 1, 2, 4]
    base = {"name": "r", "towns": ["town10"], "methods": [{"name": "oracle", "kind": "oracle"}]}
    with pytest.raises(UnknownNameError, match="method 'oracl'; valid: oracle"):
        load_experiment({**base, "sweep": {"methods.oracl.args.position_sigma_m": [1, 2]}})
    with pytest.raises(
        ConfigError, match=r"sweep.methods.oracle: .*'position_sigm'; valid: covariance, fail"
    ):
        load_experiment({**base, "sweep": {"methods.oracle.args.position_sigm": [1, 2]}})
    with pytest.raises(
        ConfigError, match=r"sweep.methods.oracle: .*position_sigma_m: must be >= 0"
    ):
        load_experiment({**base, "sweep": {"methods.oracle.args.position_sigma_m": [-1, 2]}})
    with pytest.raises(ConfigError, match="a method's kind cannot be swept"):
        load_experiment({**base, "sweep": {"methods.oracle.kind": ["map", "oracle"]}})


def test_a_requirements_run_places_a_real_method_on_the_oracle_sweep(tiny, tmp_path):
    from vlocbench.bench.report import write_report
    from vlocbench.bench.runner import run_experiment

    root, _ = tiny
    spec = yaml.safe_load((root / "tiny.yaml").read_text())
    spec.update(
        name="req",
        methods=["sift", {"name": "oracle", "kind": "oracle"}],
        sweep={"methods.oracle.args.position_sigma_m": [0.0, 3.0]},
        output=str(tmp_path / "out"),
    )
    plan = load_experiment(spec)
    summary = run_experiment(plan, progress=False)
    assert summary.errors == 0
    files = write_report(tmp_path / "out", examples=False)
    [sweep] = oracle_sweeps(files.summary, plan.spec.towns[0])
    assert sweep.method == "oracle" and sweep.sigmas_m == [0.0, 3.0]
    assert "requirements_small.png" in {p.name for p in files.figures}
    md = files.markdown.read_text()
    section = md.split("**small: how accurate must localization be?")[1].split("**")[1]
    [row] = [r for r in section.splitlines() if r.startswith("| sift | ")]
    sigma = float(row.split("|")[2])
    assert 0 < sigma < 1  # it localizes on its own map, to well under a metre
    # the verdict runs over the swept oracle; sift, the same episodes at every sigma, has no line
    verdict = md.split("**small: verdict, over methods.oracle.args.position_sigma_m")[1]
    verdict = verdict.split("\n\n**")[0]
    assert "| oracle | " in verdict and "| sift | " not in verdict
