import itertools

import numpy as np
import pytest

from vlocbench.errors import UnknownNameError
from vlocbench.sim.conditions import Illumination
from vlocbench.sim.light import (
    NOON_AMBIENT,
    NOON_DIRECT,
    air_mass,
    daylight,
    exposure_gain,
    filmic,
    sensor_noise,
    tone_curve,
)


def test_air_mass_and_daylight_follow_the_sun():
    assert air_mass(np.pi / 2) == pytest.approx(1.0, abs=0.01)
    assert air_mass(0.0) == pytest.approx(38.0, rel=0.05)  # Kasten and Young at the horizon
    base = Illumination().sun_elevation_base_rad
    noon = daylight(1.0, base, 0.0, base)
    assert (noon.direct, noon.ambient) == pytest.approx((NOON_DIRECT, NOON_AMBIENT))
    levels = [Illumination(k=k) for k in range(11)]
    light = [daylight(i.sun_intensity, i.sun_elevation_rad, 0.0, base).horizontal for i in levels]
    assert all(a > b for a, b in itertools.pairwise(light))
    # each step of k halves the sun, and near the horizon its skylight fades too
    assert light[6] / light[8] == pytest.approx(
        4 * np.sqrt(np.sin(levels[6].sun_elevation_rad) / np.sin(levels[8].sun_elevation_rad)),
        rel=0.05,
    )
    cloudy = daylight(1.0, base, 1.0, base)
    assert cloudy.direct < noon.direct and cloudy.ambient > noon.ambient


def test_exposure_gain_and_sensor_noise():
    base = Illumination().sun_elevation_base_rad
    noon = daylight(1.0, base, 0.0, base)
    dim = daylight(1 / 64, base / 64, 0.0, base)
    assert exposure_gain(noon, noon, 0.0, 100.0) == 1.0
    assert exposure_gain(dim, noon, 0.0, 1e9) == pytest.approx(noon.horizontal / dim.horizontal)
    assert exposure_gain(dim, noon, 0.0, 8.0) == 8.0  # the end of the camera's range
    assert exposure_gain(dim, noon, 10.0, 1e9) == 1.0  # headlights fill the meter
    grey = np.full((200, 200, 3), 64, np.uint8)
    rng = np.random.default_rng(0)
    low = sensor_noise(grey, 1.0, 0.02, 0.0, rng).astype(float)
    high = sensor_noise(grey, 100.0, 0.02, 0.0, rng).astype(float)
    assert low.std() == pytest.approx(np.sqrt(0.02 * 64), rel=0.15)
    assert high.std() == pytest.approx(np.sqrt(0.02 * 100 * 64), rel=0.1)
    assert np.allclose(low[..., 0], low[..., 1])  # one draw per pixel: grey noise


def test_sensor_noise_equals_its_definition_bit_for_bit():
    """The in-place arithmetic draws and rounds exactly as the formula written out, so renders (and
    every stored result keyed by them) do not change with it."""
    image = np.random.default_rng(1).integers(0, 256, (60, 80, 3), dtype=np.uint8)
    for gain in (1.0, 3.7, 40.0):
        grey = image.astype(np.float32).mean(axis=2, keepdims=True)
        sigma = np.sqrt(0.03 * gain * grey + (0.4 * gain) ** 2)
        draws = np.random.default_rng(2).standard_normal(grey.shape, np.float32)
        expected = np.clip(image.astype(np.float32) + sigma * draws + 0.5, 0, 255).astype(np.uint8)
        got = sensor_noise(image, gain, 0.03, 0.4, np.random.default_rng(2))
        np.testing.assert_array_equal(got, expected)


def test_noiseless_sensor_returns_the_render_c_ordered():
    image = np.random.default_rng(1).integers(0, 256, (60, 80, 3), dtype=np.uint8)[::-1]
    got = sensor_noise(image, 96.0, 0.0, 0.0, np.random.default_rng(2))
    np.testing.assert_array_equal(got, image)
    assert got.flags.c_contiguous


def test_filmic_curve_keeps_mid_grey_and_crushes_the_toe():
    assert filmic(np.array(0.18)) == pytest.approx(0.18, abs=1e-6)
    x = np.logspace(-6, 3, 500)
    y = filmic(x)
    assert np.all(np.diff(y) >= 0) and y[0] >= 0 and y[-1] == 1.0  # white clip beyond 1
    # deep in the toe a power law of exponent 2 slope / (toe scale ln 10) = 1.70: a tenth of
    # the light gives a fiftieth of the output, where a gamma would give a tenth
    assert filmic(np.array(1e-4)) / filmic(np.array(1e-5)) == pytest.approx(10**1.698, rel=0.02)
    assert 0.6 < filmic(np.array(1.0)) < 0.8  # the shoulder rolls white off
    assert filmic(np.array(0.0)) == pytest.approx(0.0, abs=1e-12)
    assert tone_curve("gamma") is None
    with pytest.raises(UnknownNameError, match="tone_curve 'aces'; valid: filmic, gamma"):
        tone_curve("aces")
    lut = tone_curve("filmic")
    assert lut is not None and lut.shape == (256,) and lut.dtype == np.uint8
    assert np.all(np.diff(lut.astype(int)) >= 0)
    assert lut[0] == 0 and abs(int(lut[118]) - 118) <= 1  # mid-grey's display value stays
    assert lut[15] <= 5  # 0.2 % of white: 15 grey levels through the gamma, black through it
