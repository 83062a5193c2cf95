"""The shipped NetVLAD head (`netvlad-towns`): its weights, their digest, and places found."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.conftest import CAMERA, query_pose
from vlocbench.errors import ConfigError
from vlocbench.loc.netvlad import SHIPPED, EfficientNetNetVlad, weights_digest
from vlocbench.loc.registry import RETRIEVAL, build_retrieval
from vlocbench.sim import Conditions, Illumination, Simulator, Viewpoint, Weather
from vlocbench.sim.generation import town_set_names

EXPERIMENTS = Path(__file__).parents[2] / "experiments"


def _names(item: str | dict, field: str) -> list[str]:
    return [item] if isinstance(item, str) else town_set_names(item, field)


def test_the_preset_names_the_shipped_weights_trained_on_towns_no_experiment_drives():
    assert RETRIEVAL["netvlad-towns"][1]["sha256"] == weights_digest(SHIPPED)
    head = build_retrieval("netvlad-towns")
    assert isinstance(head, EfficientNetNetVlad)
    trained_on = set(head.meta["towns"])
    assert len(trained_on) == 6 and head.meta["spec"]["validation_towns"] == 1
    for path in EXPERIMENTS.rglob("*.yaml"):
        if path.name == "retrieval_towns.yaml":
            continue
        items = yaml.safe_load(path.read_text()).get("towns", [])
        towns = {n for i, t in enumerate(items) for n in _names(t, f"{path}: towns[{i}]")}
        assert not towns & trained_on, f"{path} drives a town the head was trained on"


def test_the_shipped_head_finds_places_under_changed_conditions_more_often(
    small_town, stretch, gallery
):
    """Queries between gallery places, at dusk, at night, in the rain and fog, and from a raised
    camera: the trained head's best match is the place more often than ImageNet's GeM's."""
    heads = {name: build_retrieval(name) for name in ("netvlad-towns", "effnet-gem")}
    images = [gallery.load_image(n) for n in gallery.names]
    described = {n: np.stack([h.describe(im, None) for im in images]) for n, h in heads.items()}
    assert described["netvlad-towns"].shape == (len(images), 4096)
    assert np.allclose(np.linalg.norm(described["netvlad-towns"], axis=1), 1.0, atol=1e-5)
    again = heads["netvlad-towns"].describe(images[10], None)
    assert np.array_equal(described["netvlad-towns"][10], again)  # deterministic
    conditions = [
        Conditions(illumination=Illumination(k=6)),
        Conditions(illumination=Illumination(k=8)),
        Conditions(weather=Weather(rain=1.0, fog_visual_range_m=30)),
        Conditions(viewpoint=Viewpoint(4, 22.5)),
        Conditions(viewpoint=Viewpoint(8, 37.5)),
    ]
    found = dict.fromkeys(heads, 0)
    with Simulator(small_town) as sim:
        for index in (6, 10, 20):
            sim.teleport(*query_pose(stretch, index))  # 1 m past gallery image `index`
            for c in conditions:
                sim.set_conditions(c)
                image = sim.render([CAMERA])[0].image
                for name, head in heads.items():
                    best = int(np.argmax(described[name] @ head.describe(image, None)))
                    found[name] += best in (index, index + 1)
    # measured: 12 and 6 of 15
    assert found["netvlad-towns"] >= 10 and found["netvlad-towns"] > found["effnet-gem"]


def test_other_weights_than_the_preset_names_are_refused(tmp_path):
    changed = tmp_path / "changed.npz"
    shutil.copy(SHIPPED, changed)
    with np.load(changed) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["bias"] = arrays["bias"] + 1.0
    np.savez(changed, **arrays)
    with pytest.raises(ConfigError, match=r"retrieval\.sha256: .* the weights changed"):
        EfficientNetNetVlad(weights=str(changed), sha256=weights_digest(SHIPPED))
    assert EfficientNetNetVlad(weights=str(changed)).digest == weights_digest(changed)
    (tmp_path / "not.npz").write_text("not weights")
    with pytest.raises(ConfigError, match=r"retrieval\.weights: .* not NetVLAD weights"):
        EfficientNetNetVlad(weights=str(tmp_path / "not.npz"))
    with pytest.raises(ConfigError, match=r"retrieval\.weights: .* does not exist"):
        EfficientNetNetVlad(weights=str(tmp_path / "missing.npz"))
