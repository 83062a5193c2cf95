"""Rain's wet world: puddles that lie still and mirror the scene, wet facades, the deposits field."""

import numpy as np
import pytest

from vlocbench.config import from_dict, to_dict
from vlocbench.errors import ConfigError
from vlocbench.sim import Camera, Conditions, Exposure, Extrinsics, Intrinsics, Weather
from vlocbench.sim.rain import PUDDLE_MAX_SHARE, apply_puddles, apply_rain, puddle_mask

SKY_RGB = np.array([0.2, 0.3, 0.9])


def test_puddles_cover_their_share_of_the_road_at_the_same_places():
    x, y = np.meshgrid(np.linspace(0, 400, 300), np.linspace(-200, 200, 300))
    full, half = puddle_mask(x, y, 1.0, seed=7), puddle_mask(x, y, 0.5, seed=7)
    assert full.mean() == pytest.approx(PUDDLE_MAX_SHARE, abs=0.05)
    assert half.mean() == pytest.approx(PUDDLE_MAX_SHARE / 2, abs=0.05)
    assert not (half & ~full).any()  # more deposits only add water
    assert (puddle_mask(x, y, 1.0, seed=7) == full).all()
    assert (puddle_mask(x, y, 1.0, seed=8) != full).mean() > 0.2
    assert not puddle_mask(x, y, 0.0, seed=7).any()


def street(width=160, height=120, wall_m=20.0, camera_z_m=2.0):
    """A camera ``camera_z_m`` above a flat road, looking along it at a red wall ``wall_m`` ahead:
    the image (grey road below, red wall above), its depth, K and world_from_cam."""
    f = width / 2  # 90 deg field of view
    K = np.array([[f, 0, width / 2 - 0.5], [0, f, height / 2 - 0.5], [0, 0, 1.0]])
    rows = np.arange(height, dtype=np.float64)[:, None] - K[1, 2]
    with np.errstate(divide="ignore"):
        road_m = np.where(rows > 0, camera_z_m * f / rows, np.inf)
    depth_m = np.broadcast_to(np.minimum(road_m, wall_m), (height, width)).astype(np.float32)
    image = np.where((road_m < wall_m)[..., None], [120, 120, 120], [200, 30, 30])
    image = np.broadcast_to(image, (height, width, 3)).astype(np.uint8)
    # optical frame (x right, y down, z forward) in a world of x forward, y left, z up
    world_from_cam = np.eye(4)
    world_from_cam[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]
    world_from_cam[2, 3] = camera_z_m
    return image, depth_m, K, world_from_cam


def test_puddles_darken_the_road_and_mirror_the_wall():
    image, depth_m, K, world_from_cam = street()
    out = apply_puddles(
        image, depth_m, K, world_from_cam, 1.0, 3, SKY_RGB, np.random.default_rng(0)
    )
    road = depth_m < 20.0
    changed = (out != image).any(axis=2)
    assert changed.any() and not changed[~road].any()  # the wall stays dry
    assert 0.2 < changed[road].mean() < 0.8
    wet = out[changed].astype(int)
    assert (wet.sum(axis=1) < 3 * 120).mean() > 0.9  # water darkens the asphalt under it
    # 6-10 m ahead the water mirrors the red wall (Fresnel's 17-35 %: more towards the horizon);
    # nearer the wall's foot the ripples mix in the road
    far = changed & (depth_m > 6.0) & (depth_m < 10.0)
    assert far.any()
    assert (out[far][:, 0].astype(int) - out[far][:, 1] > 20).all()
    dry = apply_puddles(
        image, depth_m, K, world_from_cam, 0.0, 3, SKY_RGB, np.random.default_rng(0)
    )
    assert (dry == image).all()


def test_puddles_lie_on_the_road_of_a_render_and_wet_walls_are_darker(small_sim):
    wp = small_sim.town.route.waypoints_xy[10]
    small_sim.teleport(float(wp[0]), float(wp[1]), float(small_sim.town.route.yaw_rad[10]))
    ahead = Camera("g", Intrinsics(320, 240, 90.0), Extrinsics(yaw_deg=0.0))
    fixed = Exposure("fixed")

    def image(weather):
        small_sim.set_conditions(Conditions(weather=weather, exposure=fixed))
        return small_sim.render([ahead], frame_id=10)[0].image.astype(int)

    still, puddles = image(Weather(rain=1.0, deposits=0.0)), image(Weather(rain=1.0))
    changed = np.nonzero((still != puddles).any(axis=2))
    assert len(changed[0]) > 100
    assert changed[0].min() >= 120  # below the horizon: on the road, nowhere above
    dry, wet = image(Weather()), image(Weather(wetness=1.0))
    assert wet[:120].mean() < dry[:120].mean() - 2  # the facades above the horizon
    assert (image(Weather(deposits=0.0)) == dry).all()


def test_deposits_out_of_range_name_the_field():
    with pytest.raises(ConfigError, match=r"weather\.deposits.*\[0, 1\]"):
        from_dict(Conditions, {"weather": {"deposits": 1.5}})
    assert Weather(rain=0.8).puddles == 0.8 and Weather(rain=0.8, deposits=0.1).puddles == 0.1


def test_the_streak_density_is_the_rains_knob():
    """More streaks per 1000 pixels brighten more of the image; none leave the veil and noise."""
    image = np.full((120, 160, 3), 60, np.uint8)
    streaked = {
        density: (apply_rain(image, 1.0, 0.5, density, np.random.default_rng(0)) > 110).mean()
        for density in (0.0, 0.45, 1.5)
    }
    assert streaked[0.0] == 0.0 < streaked[0.45] < streaked[1.5]
    with pytest.raises(ConfigError, match=r"weather\.rain_streaks_per_kpx: must be >= 0"):
        Weather(rain=1.0, rain_streaks_per_kpx=-1)


def test_the_streak_density_keys_only_rainy_results():
    """Dry conditions keep their keys whatever the density; rain at the density fitted before
    (0.45) keeps its stored keys; rain at today's default gets new ones."""
    from vlocbench.config import config_hash

    assert config_hash(Weather(rain_streaks_per_kpx=2.0)) == config_hash(Weather())
    before = to_dict(Weather(rain=1.0))
    del before["rain_streaks_per_kpx"]
    del before["deposits"]  # an option added later, left out at its default
    assert config_hash(Weather(rain=1.0, rain_streaks_per_kpx=0.45)) == config_hash(before)
    assert config_hash(Weather(rain=1.0)) != config_hash(before)
