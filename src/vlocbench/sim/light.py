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

Between the exposure and the encoding, CARLA's camera (Unreal Engine 4's post-process, which the
paper's code leaves at its defaults) applies a filmic tone curve: in log10 of the scene-linear
value it is a straight line of slope 0.88 through mid-grey (0.18 in, 0.18 out), joined to a
logistic toe below and shoulder above. Its toe crushes what a plain gamma keeps: a facade at 0.2 %
of white, 15 grey levels through the gamma, is black through the curve. ``tone_curve("filmic")``
is that curve; ``"gamma"`` (vlocbench's camera) leaves the image as rendered.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from vlocbench.config import require_one_of

NOON_DIRECT = 0.7  # diffuse colour of the sun light at noon (MuJoCo light units)
NOON_AMBIENT = 0.35  # ambient (sky) light at noon
BEAM_TRANSMITTANCE = 0.7  # Meinel and Meinel: beam fraction through one clear air mass
DISPLAY_GAMMA = 2.2  # the camera's output encoding: display value = linear ** (1 / 2.2)
ToneCurve = Literal["filmic", "gamma"]
TONE_CURVES: tuple[str, ...] = get_args(ToneCurve)
# UE4's filmic tone mapper at the defaults of CARLA's RGB camera (its blueprint's slope, toe,
# shoulder, black_clip and white_clip attributes)
FILM_SLOPE = 0.88
FILM_TOE = 0.55
FILM_SHOULDER = 0.26
FILM_BLACK_CLIP = 0.0
FILM_WHITE_CLIP = 0.04
FILM_MID_GREY = 0.18  # the curve leaves mid-grey where it is


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


def filmic(linear: np.ndarray) -> np.ndarray:
    """UE4's filmic tone curve at CARLA's defaults on scene-linear values at the metered exposure
    (any shape, >= 0), per channel (without the ACES colour transforms around it); the output is
    linear in [0, 1], before the display encoding."""
    toe_scale = 1 + FILM_BLACK_CLIP - FILM_TOE
    shoulder_scale = 1 + FILM_WHITE_CLIP - FILM_SHOULDER
    # mid-grey on the toe (FILM_TOE <= 0.8): where the toe's logistic passes through it
    b = (FILM_MID_GREY + FILM_BLACK_CLIP) / toe_scale - 1
    toe_at = np.log10(FILM_MID_GREY) - 0.5 * np.log((1 + b) / (1 - b)) * toe_scale / FILM_SLOPE
    offset = (1 - FILM_TOE) / FILM_SLOPE - toe_at  # the straight part: slope * (log + offset)
    shoulder_at = FILM_SHOULDER / FILM_SLOPE - offset
    with np.errstate(over="ignore"):
        # black (and below) at 1e-12: far down the toe, so the curve gives 0 there
        log = np.log10(np.maximum(np.asarray(linear, np.float64), 1e-12))
        straight = FILM_SLOPE * (log + offset)
        toe = -FILM_BLACK_CLIP + 2 * toe_scale / (
            1 + np.exp(-2 * FILM_SLOPE / toe_scale * (log - toe_at))
        )
        shoulder = (1 + FILM_WHITE_CLIP) - 2 * shoulder_scale / (
            1 + np.exp(2 * FILM_SLOPE / shoulder_scale * (log - shoulder_at))
        )
    low = np.where(log < toe_at, toe, straight)
    high = np.where(log > shoulder_at, shoulder, straight)
    # a smooth blend from the toe to the shoulder (at these defaults the two overlap, the
    # shoulder starting below the toe's end, so the blend runs the other way)
    t = np.clip((log - toe_at) / (shoulder_at - toe_at), 0.0, 1.0)
    if shoulder_at < toe_at:
        t = 1 - t
    t = t * t * (3 - 2 * t)
    return np.clip(low + (high - low) * t, 0.0, 1.0)


def tone_curve(name: str) -> np.ndarray | None:
    """The camera's tone curve as a lookup table over the rendered (display-encoded) grey levels,
    (256,) uint8, or None for ``gamma`` (the render as it is)."""
    require_one_of(name, TONE_CURVES, "tone_curve")
    if name == "gamma":
        return None
    display = np.arange(256) / 255.0
    toned = filmic(display**DISPLAY_GAMMA) ** (1 / DISPLAY_GAMMA)
    return np.round(255 * toned).astype(np.uint8)
