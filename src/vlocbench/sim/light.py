"""Daylight and the camera's exposure, from the sun's intensity and elevation (pure numerics).

The paper's illumination levels scale the sun's intensity I and its elevation by 0.5^k. The light
that reaches the town follows from them physically, relative to noon (k = 0, elevation 75 deg):

- direct sunlight: I times the clear-sky transmittance of the air mass it crosses, tau^(m^0.678)
  (Meinel and Meinel's beam model, tau = 0.7; air mass m from Kasten and Young's formula), which
  falls steeply as the sun nears the horizon;
- skylight (the scene's ambient light): scattered sunlight, I times sqrt(sin(elevation)), the
  low-sun dependence of clear-sky diffuse irradiance;
- overcast moves light from the sun to the sky.

The camera meters that light and opens up (longer exposure, then gain) by up to ``max_gain``
(its exposure range). The scene is rendered as the camera records it: at the metered exposure
where it reaches that; beyond its range it reaches only a share e < 1 of it, and its
gamma-encoded output (display = linear^(1/2.2), as sRGB and CARLA's tone curve) is darker by
e^(1/2.2): every light of the scene is scaled by it, so the 8-bit quantization comes once, last.
The town's own lights (street lamps, lit windows) are set in the same display values. Sensor
noise grows with the gain: photon shot noise (variance ``shot_noise * gain`` per grey level) and
read noise (``read_noise * gain``). The camera's range is fitted once, on the recall the paper
measured at one level (``benchmarks/bench_illumination.py``; docs/calibration.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NOON_DIRECT = 0.7  # diffuse colour of the sun light at noon (MuJoCo light units)
NOON_AMBIENT = 0.35  # ambient (sky) light at noon
BEAM_TRANSMITTANCE = 0.7  # Meinel and Meinel: beam fraction through one clear air mass
DISPLAY_GAMMA = 2.2  # the camera's output encoding: display value = linear ** (1 / 2.2)


def air_mass(elevation_rad: float) -> float:
    """Relative optical air mass at a solar elevation (Kasten and Young, 1989)."""
    el_deg = max(float(np.degrees(elevation_rad)), 0.0)
    return 1.0 / (np.sin(np.radians(el_deg)) + 0.50572 * (el_deg + 6.07995) ** -1.6364)


def beam_transmittance(elevation_rad: float) -> float:
    """Share of the sun's light that reaches the ground through a clear sky."""
    return float(BEAM_TRANSMITTANCE ** (air_mass(elevation_rad) ** 0.678))


@dataclass(frozen=True)
class Daylight:
    """Sun (``direct``) and sky (``ambient``) light in MuJoCo's light units, before exposure."""

    direct: float
    ambient: float

    @property
    def horizontal(self) -> float:
        """What a light meter facing up reads, relative units."""
        return self.direct + self.ambient


def daylight(
    intensity: float, elevation_rad: float, overcast: float, noon_elevation_rad: float
) -> Daylight:
    """The light of a sun of relative ``intensity`` at ``elevation_rad``; at intensity 1 and the
    noon elevation it is NOON_DIRECT and NOON_AMBIENT."""
    el = max(elevation_rad, 0.0)
    beam = beam_transmittance(el) / beam_transmittance(noon_elevation_rad)
    sky = np.sqrt(np.sin(el) / np.sin(noon_elevation_rad))
    direct = NOON_DIRECT * intensity * beam * (1 - 0.75 * overcast)
    ambient = NOON_AMBIENT * intensity * sky * (1 + 0.25 * overcast)
    return Daylight(float(direct), float(ambient))


def exposure_gain(light: Daylight, reference: Daylight, extra: float, max_gain: float) -> float:
    """The camera's gain: the noon reading over this one (``extra``: other light the meter sees,
    such as headlights), at least 1 and at most ``max_gain``."""
    reading = light.horizontal + extra
    return float(np.clip(reference.horizontal / max(reading, 1e-12), 1.0, max_gain))


def sensor_noise(
    image: np.ndarray,
    gain: float,
    shot_noise: float,
    read_noise: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """``image`` (H, W, 3) uint8, rendered at the exposure the camera reached, with the shot and
    read noise of a sensor at ``gain``: per pixel sigma^2 = shot_noise * gain * grey +
    (read_noise * gain)^2 (grey levels), one draw per pixel."""
    if shot_noise == 0 and read_noise == 0:
        return np.ascontiguousarray(image)
    rgb = image.astype(np.float32)
    # the channels' mean summed in order: in float32 exactly numpy's mean, without its slow reduce
    grey = rgb[..., 0] + rgb[..., 1]
    grey += rgb[..., 2]
    grey /= 3
    variance = grey * (shot_noise * gain)
    variance += (read_noise * gain) ** 2
    noise = np.sqrt(variance, out=variance)
    noise *= rng.standard_normal(grey.shape, np.float32)
    rgb += noise[..., None]
    rgb += 0.5
    return np.clip(rgb, 0, 255, out=rgb).astype(np.uint8)
