"""Towns drawn from a distribution: pure in their seed, different from each other, routes of the
paper's kind, and a hidden set whose seed comes only from the environment."""

import itertools

import pytest

from vlocbench.config import to_dict
from vlocbench.errors import ConfigError
from vlocbench.sim import generation
from vlocbench.sim.generation import (
    HIDDEN_SEED_ENV,
    HIDDEN_SEED_FILE_ENV,
    ROUTE_BY_STYLE,
    TownSet,
    seed_digest,
    town_set_names,
)
from vlocbench.sim.town import generate_town, load_town_spec

HIDDEN_SEED = 2**50 + 12345


@pytest.mark.parametrize("style", ["town", "city"])
def test_a_set_is_a_pure_function_of_its_seed_and_its_towns_differ(style):
    names = TownSet(4, style, seed=7).names()
    specs = [load_town_spec(n) for n in names]
    assert [to_dict(load_town_spec(n)) for n in names] == [to_dict(s) for s in specs]
    layouts = {(s.block_widths_m, s.block_depths_m, s.route.nodes) for s in specs}
    assert len(layouts) == len(specs)
    other = load_town_spec(f"gen-{style}-8-0")
    assert to_dict(other) != to_dict(specs[0])
    assert all(s.style == style and s.name == n for s, n in zip(specs, names))


@pytest.mark.parametrize("style", ["town", "city"])
def test_routes_are_the_papers_kind_with_buildings_on_the_camera_side(style):
    length_m, turns = ROUTE_BY_STYLE[style]
    for name in TownSet(6, style, seed=3).names():
        spec = load_town_spec(name)
        town = generate_town(spec)
        assert town.route.num_turns == turns
        assert abs(town.route.length_m - length_m) <= 0.05 * length_m
        nodes = spec.route.nodes
        assert len(set(nodes)) == len(nodes)  # it never comes back to an intersection
        nx_, ny_ = len(spec.block_widths_m), len(spec.block_depths_m)
        parks = {tuple(p) for p in spec.parks}
        for a, b in itertools.pairwise(nodes):
            for part in generation._right_side(a, b, nx_, ny_):
                assert part not in parks and part != spec.beach_side, (name, a, b, part)


def test_a_generated_town_is_a_town_like_the_built_in_ones():
    town = generate_town(load_town_spec("gen-city-5-2"))
    assert any(b.tower for b in town.buildings) and len(town.lamps) > 20
    assert town.spec.road.lanes_per_direction == 2


def test_a_set_out_of_range_names_its_field():
    with pytest.raises(ConfigError, match=r"towns\[1\].generate.count: must be in \[1, 64\]"):
        town_set_names({"generate": {"count": 0}}, "towns[1]")
    with pytest.raises(
        ConfigError, match=r"towns\[0\].generate.style 'village'; valid: city, town"
    ):
        town_set_names({"generate": {"count": 2, "style": "village"}}, "towns[0]")
    with pytest.raises(
        ConfigError, match=r"^towns\[0\]\.generate: unknown key 'sede'; valid: count, seed, style$"
    ):
        town_set_names({"generate": {"count": 2, "sede": 3}}, "towns[0]")
    with pytest.raises(ConfigError, match=r"towns\[0\]: expected a town name, \{generate"):
        town_set_names({"make": {"count": 2}}, "towns[0]")


def test_the_hidden_seed_comes_only_from_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv(HIDDEN_SEED_ENV, raising=False)
    monkeypatch.delenv(HIDDEN_SEED_FILE_ENV, raising=False)
    with pytest.raises(ConfigError, match=f"{HIDDEN_SEED_ENV}: hidden towns need"):
        town_set_names({"hidden": {"count": 2}}, "towns[0]")
    with pytest.raises(ConfigError, match=r"towns\[0\].hidden.seed: a hidden set's seed is never"):
        town_set_names({"hidden": {"count": 2, "seed": 5}}, "towns[0]")
    monkeypatch.setenv(HIDDEN_SEED_FILE_ENV, str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match=f"{HIDDEN_SEED_FILE_ENV}: cannot read .*missing"):
        town_set_names({"hidden": {"count": 2}}, "towns[0]")
    (tmp_path / "seed").write_text("1234\n")
    monkeypatch.setenv(HIDDEN_SEED_FILE_ENV, str(tmp_path / "seed"))
    with pytest.raises(ConfigError, match="must be at least 2\\*\\*40"):
        town_set_names({"hidden": {"count": 2}}, "towns[0]")
    (tmp_path / "seed").write_text(f"{HIDDEN_SEED}\n")
    names = town_set_names({"hidden": {"count": 2, "style": "city"}}, "towns[0]")
    assert names == [f"hidden-{seed_digest(HIDDEN_SEED)}-city-{i}" for i in range(2)]
    assert str(HIDDEN_SEED) not in "".join(names)
    hidden = load_town_spec(names[0])
    # the towns are drawn as any generated town, from the seed nobody else sees
    assert hidden.block_widths_m == load_town_spec(f"gen-city-{HIDDEN_SEED}-0").block_widths_m
    monkeypatch.setenv(HIDDEN_SEED_ENV, str(HIDDEN_SEED + 1))  # the variable wins over the file
    with pytest.raises(ConfigError, match="was drawn from a hidden seed with digest"):
        load_town_spec(names[0])
