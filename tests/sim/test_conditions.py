import pytest

from vlocbench.config import config_hash, from_dict, hashed_values
from vlocbench.errors import ConfigError, UnknownNameError
from vlocbench.sim import Conditions, Exposure, Illumination, Intrinsics, Weather


def test_illumination_halves_intensity_and_elevation():
    a, b = Illumination(k=0), Illumination(k=2)
    assert b.sun_intensity == pytest.approx(a.sun_intensity / 4)
    assert b.sun_elevation_rad == pytest.approx(a.sun_elevation_rad / 4)


def test_the_lights_own_clouds_follow_the_suns_intensity():
    assert Conditions(illumination=Illumination(k=2)).overcast == 0.0
    clouded = Illumination(k=2, cloud_cover="from_intensity")
    assert Conditions(illumination=clouded).overcast == pytest.approx(0.75)
    assert Conditions(illumination=Illumination(k=0, cloud_cover="from_intensity")).overcast == 0
    heavier = Conditions(illumination=clouded, weather=Weather(overcast=0.9))
    assert heavier.overcast == pytest.approx(0.9)
    # an option added after results were stored: at its default, no key changes
    assert config_hash(Illumination(k=2)) != config_hash(clouded)
    assert "cloud_cover" not in str(hashed_values(Illumination(k=2)))


def test_bad_values_name_their_field():
    with pytest.raises(ConfigError, match=r"illumination\.k"):
        Illumination(k=-1)
    with pytest.raises(ConfigError, match=r"fog_visual_range_m"):
        Weather(fog_visual_range_m=-5)
    with pytest.raises(
        ConfigError, match="unknown fog_model 'linear'; valid: exponential, starts_at"
    ):
        from_dict(Weather, {"fog_model": "linear"})
    with pytest.raises(ConfigError, match=r"fov_deg"):
        Intrinsics(fov_deg=180)
    with pytest.raises(ConfigError, match=r"fov_deg"):
        Intrinsics(fov_deg=0)
    with pytest.raises(UnknownNameError, match="autumn, summer, winter"):
        Conditions(season="spring")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"exposure\.max_gain"):
        Exposure(max_gain=0.5)
    with pytest.raises(ConfigError, match=r"exposure\.shot_noise: must be >= 0"):
        Exposure(shot_noise=-0.1)
    with pytest.raises(ConfigError, match=r"exposure\.read_noise: must be >= 0"):
        Exposure(read_noise=-1.0)
    with pytest.raises(UnknownNameError, match="tone_curve 'aces'; valid: filmic, gamma"):
        from_dict(Exposure, {"tone_curve": "aces"})
    with pytest.raises(ConfigError, match=r"weather\.fog_ramp_m: must be > 0"):
        Weather(fog_visual_range_m=30, fog_ramp_m=0)
    with pytest.raises(UnknownNameError, match="valid: exponential, starts_at"):
        Weather(fog_model="haze")  # type: ignore[arg-type]
    with pytest.raises(UnknownNameError, match="valid: auto, fixed"):
        from_dict(Conditions, {"exposure": {"mode": "manual"}})
    with pytest.raises(
        UnknownNameError,
        match=r"^illumination: unknown cloud cover 'overcast'; valid: clear, from_intensity$",
    ):
        Illumination(cloud_cover="overcast")


def test_from_dict_builds_nested_conditions_and_hashes_stably():
    c = from_dict(Conditions, {"illumination": {"k": 3}, "weather": {"fog_visual_range_m": 30}})
    assert c.illumination.k == 3.0 and c.weather.fog_density_per_m == pytest.approx(0.1)
    assert config_hash(c) == config_hash(
        from_dict(Conditions, {"illumination": {"k": 3.0}, "weather": {"fog_visual_range_m": 30.0}})
    )
    assert config_hash(c) != config_hash(Conditions())
    with pytest.raises(ConfigError, match=r"weather\.rain"):
        from_dict(Conditions, {"weather": {"rain": "heavy"}})
