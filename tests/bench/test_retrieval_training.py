"""Training the NetVLAD head on real renders of two small towns: seeded, and it learns."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
import yaml

from tests.conftest import small_spec
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.retrieval_training import (
    RetrievalTraining,
    TrainingSet,
    conditions_from,
    held_out_recall,
    render_record,
    render_training_set,
    train_netvlad,
)
from vlocbench.config import to_dict
from vlocbench.errors import ConfigError
from vlocbench.loc.netvlad import EfficientNetNetVlad, initial_params, save_weights

SPEC = RetrievalTraining(
    query_spacing_m=5.0, dim=16, clusters=4, epochs=4, batch=4, negatives=3, width=160
)


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    """Two small towns' experiment file and a conditions file (noon and dusk), written."""
    root = tmp_path_factory.mktemp("training")
    towns = []
    for seed in (3, 4):
        path = root / f"small{seed}.yaml"
        path.write_text(yaml.safe_dump({**to_dict(small_spec(seed)), "name": f"small{seed}"}))
        towns.append(str(path))
    plan = {
        "name": "training",
        "towns": towns,
        "route_length_m": 60,
        "methods": ["sift"],
        "gallery": {"camera": {"intrinsics": {"width": 320, "height": 240}}},
        "cache": str(root / "cache"),
    }
    conditions = {
        "name": "c",
        "towns": towns,
        "methods": ["sift"],
        "sweep": {"illumination.k": [0, 6]},
    }
    (root / "towns.yaml").write_text(yaml.safe_dump(plan))
    (root / "light.yaml").write_text(yaml.safe_dump(conditions))
    return root / "towns.yaml", root / "light.yaml"


@pytest.fixture(scope="module")
def training_set(sources):
    towns, light = sources
    return render_training_set(load_experiment(towns), conditions_from([light]), SPEC)


def test_the_set_holds_each_towns_gallery_and_queries_and_reads_back(training_set, tmp_path):
    data = training_set
    assert data.towns == ("small3", "small4") and data.setups == (
        "light: illumination.k=0",
        "light: illumination.k=6",
    )
    assert data.gallery_maps.dtype == np.float16 and data.gallery_maps.shape[1:] == (1280, 3, 5)
    assert set(data.gallery_town) == {0, 1} and set(data.query_town) == {0, 1}
    assert len(data.query_xy) == 2 * int(60 / SPEC.query_spacing_m)
    assert set(data.query_setup) == {0, 1}
    data.save(str(tmp_path / "set.npz"))
    again = TrainingSet.load(str(tmp_path / "set.npz"))
    assert again.towns == data.towns and again.setups == data.setups
    assert again.rendered_with == data.rendered_with
    assert data.rendered_with["width"] == SPEC.width and len(data.rendered_with["sources"]) == 16
    assert np.array_equal(again.query_maps, data.query_maps)
    assert np.array_equal(again.gallery_xy, data.gallery_xy)


def test_training_lowers_the_loss_ranks_places_better_and_is_seeded(training_set, tmp_path):
    data = training_set
    first = initial_params(torch.from_numpy(data.gallery_maps), SPEC.dim, SPEC.clusters)
    params, report = train_netvlad(data, SPEC)
    assert len(report.loss) == SPEC.epochs and report.loss[-1] < report.loss[0]
    assert set(report.recall_by_setup) == set(data.setups)  # the held-out town, per setup
    trained = np.array([0])  # the training town: its places ranked at least as well
    before = held_out_recall(first, data, trained, SPEC.positive_m)["all"]
    after = held_out_recall(params, data, trained, SPEC.positive_m)["all"]
    assert after[0] >= before[0] and after[1] >= before[1]
    again, _ = train_netvlad(data, SPEC)
    assert all(torch.equal(params[k], again[k]) for k in params)
    # written, the head describes an image as a (K * D,) unit vector, and names its digest
    path = tmp_path / "head.npz"
    digest = save_weights(path, params, {"towns": list(data.towns)})
    head = EfficientNetNetVlad(weights=str(path), sha256=digest, width=160, device="cpu")
    assert head.meta == {"towns": ["small3", "small4"]}
    image = np.zeros((240, 320, 3), np.uint8)
    image[:, 160:] = 200
    v = head.describe(image, None)
    assert v.shape == (SPEC.dim * SPEC.clusters,) and abs(float(np.linalg.norm(v)) - 1) < 1e-5


def test_bad_training_values_name_the_field(training_set):
    with pytest.raises(ConfigError, match=r"training\.negative_m"):
        RetrievalTraining(positive_m=10, negative_m=5)
    with pytest.raises(ConfigError, match=r"training\.clusters"):
        RetrievalTraining(clusters=0)
    with pytest.raises(ConfigError, match=r"training\.validation_towns: leaves no town"):
        train_netvlad(training_set, RetrievalTraining(validation_towns=2))


def test_the_command_trains_from_a_rendered_set_and_records_how(
    training_set, sources, tmp_path, capsys
):
    from vlocbench.cli import main
    from vlocbench.loc.netvlad import load_weights, weights_digest

    towns, light = sources
    argv = ["train-retrieval", str(towns), "--conditions", str(light), "--epochs", "1"]
    # the fixture's set, rendered with SPEC's values, is refused by a run of the defaults
    data = tmp_path / "set.npz"
    training_set.save(str(data))
    out = tmp_path / "head.npz"
    assert main([*argv, "--output", str(out), "--data", str(data)]) == ConfigError.exit_code
    assert "error: training.query_spacing_m: " in capsys.readouterr().err
    assert not out.exists()
    # the same set as a run of the defaults would render it: read, not rendered again
    default = render_record(load_experiment(towns), conditions_from([light]), RetrievalTraining())
    dataclasses.replace(training_set, rendered_with=default).save(str(data))
    assert main([*argv, "--output", str(out), "--data", str(data)]) == 0
    arrays, meta = load_weights(out)
    assert arrays["proj"].shape == (128, 1280) and arrays["centroids"].shape == (32, 128)
    assert meta["towns"] == ["small3", "small4"] and meta["spec"]["epochs"] == 1
    assert meta["rendered_with"] == default
    assert len(meta["loss"]) == 1 and set(meta["held_out_recall_by_setup"]) == set(
        training_set.setups
    )
    assert f"digest {weights_digest(out)}" in capsys.readouterr().out
    # other conditions than the set's, or a set that does not say how it was rendered
    argv[3] = str(towns)  # the conditions of the towns file: noon alone
    assert main([*argv, "--output", str(out), "--data", str(data)]) == ConfigError.exit_code
    assert "error: towns and --conditions: " in capsys.readouterr().err
    arrays = dict(np.load(data))
    del arrays["rendered_with"]
    np.savez(data, **arrays)
    assert main([*argv, "--output", str(out), "--data", str(data)]) == ConfigError.exit_code
    assert "does not record what it was rendered from" in capsys.readouterr().err
