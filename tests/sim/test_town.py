import dataclasses

import numpy as np
import pytest

from tests.conftest import small_spec
from vlocbench.config import from_dict
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.sim.town import TownSpec, builtin_town_names, generate_town, load_town_spec


def test_generation_is_deterministic_in_the_seed():
    a, b = generate_town(small_spec(3)), generate_town(small_spec(3))
    assert a.buildings == b.buildings
    np.testing.assert_array_equal(a.trees, b.trees)
    c = generate_town(small_spec(4))
    assert c.buildings != a.buildings


@pytest.mark.parametrize(("name", "length_m", "turns"), [("town01", 1200, 5), ("town10", 500, 6)])
def test_builtin_routes_match_the_papers(name, length_m, turns):
    town = generate_town(load_town_spec(name))
    assert abs(town.route.length_m - length_m) <= 0.05 * length_m
    assert town.route.num_turns == turns
    steps = np.linalg.norm(np.diff(town.route.waypoints_xy, axis=0), axis=1)
    np.testing.assert_allclose(steps[:-1], 2.0, atol=0.01)  # chords of 2 m arcs on the turns
    assert 0 < steps[-1] <= 2.0 + 1e-9


def test_a_route_far_from_its_target_length_is_refused():
    spec = load_town_spec("town10")
    route = dataclasses.replace(spec.route, target_length_m=800.0)
    with pytest.raises(
        ConfigError,
        match=r"route\.target_length_m: the route's nodes and offsets "
        r"give 489 m, more than 10% off 800",
    ):
        generate_town(dataclasses.replace(spec, route=route))


def test_town10_is_repetitive_and_tall():
    t01, t10 = (generate_town(load_town_spec(n)) for n in ("town01", "town10"))
    assert t10.spec.buildings.facade_styles < t01.spec.buildings.facade_styles
    assert max(b.height_m for b in t10.buildings) > 3 * max(b.height_m for b in t01.buildings)
    assert t10.sand and t10.water and not t01.water


def test_unknown_town_lists_the_builtin_ones():
    with pytest.raises(UnknownNameError) as err:
        load_town_spec("town99")
    for name in builtin_town_names():
        assert name in str(err.value)


def test_bad_spec_values_name_the_field():
    with pytest.raises(ConfigError, match=r"block_widths_m\[1\]"):
        dataclasses.replace(small_spec(), block_widths_m=(50.0, 10.0))
    with pytest.raises(ConfigError, match=r"^TownSpec: unknown key 'colour'; valid: "):
        from_dict(TownSpec, {"name": "x", "colour": 1})
    with pytest.raises(ConfigError, match=r"route.nodes\[1\]"):
        spec = small_spec()
        bad = dataclasses.replace(
            spec, route=dataclasses.replace(spec.route, nodes=((0, 0), (1, 0), (2, 0)))
        )
        generate_town(bad)


def test_user_town_from_yaml(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text(
        "name: mine\nseed: 5\nblock_widths_m: [60, 60]\nblock_depths_m: [55]\n"
        "route: {nodes: [[0, 0], [2, 0], [2, 1]], start_offset_m: 12, end_offset_m: 12}\n"
    )
    town = generate_town(load_town_spec(path))
    assert town.name == "mine" and town.route.num_turns == 1 and len(town.buildings) > 5
