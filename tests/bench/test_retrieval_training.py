"""Training the NetVLAD head on real renders of two small towns: seeded, and it learns."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import yaml

from tests.conftest import small_spec
from vlocbench.bench.experiment import load_experiment
from vlocbench.bench.retrieval_training import (
    RetrievalTraining,
    TrainingSet,
    held_out_recall,
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
def training_set(tmp_path_factory):
    root = tmp_path_factory.mktemp("training")
    towns = []
    for seed in (3, 4):
        path = root / f"small{seed}.yaml"
        path.write_text(yaml.safe_dump({**to_dict(small_spec(seed)), "name": f"small{seed}"}))
        towns.append(str(path))
    plan = load_experiment(
        {
            "name": "training",
            "towns": towns,
            "route_length_m": 60,
            "methods": ["sift"],
            "gallery": {"camera": {"intrinsics": {"width": 320, "height": 240}}},
            "cache": str(root / "cache"),
        }
    )
    conditions = load_experiment(
        {"name": "c", "towns": towns, "methods": ["sift"], "sweep": {"illumination.k": [0, 6]}}
    )
    setups = [(s.label, s.conditions) for s in conditions.setups]
    return render_training_set(plan, setups, SPEC)


def test_the_set_holds_each_towns_gallery_and_queries_and_reads_back(training_set, tmp_path):
    data = training_set
    assert data.towns == ("small3", "small4") and data.setups == (
        "illumination.k=0",
        "illumination.k=6",
    )
    assert data.gallery_maps.dtype == np.float16 and data.gallery_maps.shape[1:] == (1280, 3, 5)
    assert set(data.gallery_town) == {0, 1} and set(data.query_town) == {0, 1}
    assert len(data.query_xy) == 2 * int(60 / SPEC.query_spacing_m)
    assert set(data.query_setup) == {0, 1}
    data.save(str(tmp_path / "set.npz"))
    again = TrainingSet.load(str(tmp_path / "set.npz"))
    assert again.towns == data.towns and again.setups == data.setups
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


def test_the_command_trains_from_a_rendered_set_and_records_how(training_set, tmp_path, capsys):
    from vlocbench.cli import main
    from vlocbench.loc.netvlad import load_weights, weights_digest

    data = tmp_path / "set.npz"
    training_set.save(str(data))
    towns = tmp_path / "towns.yaml"
    towns.write_text(yaml.safe_dump({"name": "t", "towns": ["town10"], "methods": ["sift"]}))
    out = tmp_path / "head.npz"
    argv = ["train-retrieval", str(towns), "--conditions", str(towns), "--output", str(out)]
    assert main([*argv, "--data", str(data), "--epochs", "1"]) == 0  # the set read, not rendered
    arrays, meta = load_weights(out)
    assert arrays["proj"].shape == (128, 1280) and arrays["centroids"].shape == (32, 128)
    assert meta["towns"] == ["small3", "small4"] and meta["spec"]["epochs"] == 1
    assert len(meta["loss"]) == 1 and set(meta["held_out_recall_by_setup"]) == set(
        training_set.setups
    )
    assert f"digest {weights_digest(out)}" in capsys.readouterr().out
