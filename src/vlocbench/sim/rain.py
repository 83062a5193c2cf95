"""Rain as the camera sees it: streaks, drops on the lens, a veil of spray, sensor noise (an image
post-process, as CARLA's screen drops are one), and puddles on the road that mirror the scene.

Deterministic for a given ``rng``. The rain costs about 25 ms at 800x600.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
from numpy.typing import NDArray

from vlocbench.interfaces import Array, Image

PUDDLE_CELL_M = 2.5  # the size of the noise's features: puddles a few metres across
PUDDLE_MAX_SHARE = 0.5  # of the road under water at deposits 1 (CARLA's precipitation_deposits 100)
PUDDLE_MAX_Z_M = 0.03  # puddles lie on the road (z = 0), not on sidewalks and kerbs
_MARCH_T_M = np.geomspace(0.3, 150.0, 20)  # samples along a reflected ray (m)
_MARCH_STEP_M = np.diff(_MARCH_T_M, prepend=0.0).astype(np.float32)  # from the sample before


def apply_rain(
    image: Image,
    amount: float,
    brightness: float,
    streaks_per_kpx: float,
    rng: np.random.Generator,
) -> Image:
    """Rain of strength ``amount`` in [0, 1] on an (H, W, 3) image; ``brightness`` in [0, 1] of the
    sky; ``streaks_per_kpx`` streaks per 1000 pixels at ``amount`` 1."""
    if amount <= 0:
        return image
    h, w = image.shape[:2]
    out = image.astype(np.float32)
    # veil: spray and scattering lower the contrast towards a grey
    veil = 255 * (0.55 * brightness + 0.05)
    out = out * (1 - 0.25 * amount) + veil * 0.25 * amount
    # streaks: short slanted bright lines, blurred along their direction
    layer = np.zeros((h, w), np.float32)
    n = int(amount * streaks_per_kpx * h * w / 1000)
    xs, ys = rng.integers(0, w, n), rng.integers(0, h, n)
    lengths = rng.integers(h // 40, h // 12, n)
    slant = rng.normal(0.15, 0.03)
    for x, y, length in zip(xs, ys, lengths):
        cv2.line(layer, (int(x), int(y)), (int(x + slant * length), int(y + length)), 1.0, 1)
    blurred_layer = cv2.GaussianBlur(layer, (3, 3), 0)
    out += blurred_layer[..., None] * 255 * (0.25 + 0.35 * brightness)
    # drops on the lens: blurred, slightly brighter discs
    for _ in range(int(amount * 14)):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        r = int(rng.integers(h // 60, h // 25))
        x0, x1, y0, y1 = max(0, x - r), min(w, x + r), max(0, y - r), min(h, y + r)
        patch = out[y0:y1, x0:x1]
        blurred = cv2.GaussianBlur(patch, (0, 0), r / 2)
        disc = np.zeros(patch.shape[:2], np.float32)
        cv2.circle(disc, (x - x0, y - y0), r, 1.0, -1)
        mask = cv2.GaussianBlur(disc, (0, 0), max(1, r / 4))[..., None]
        out[y0:y1, x0:x1] = patch * (1 - mask) + (blurred * 1.05 + 6) * mask
    out += rng.normal(0, 2 + 3 * amount, (h, w, 1))
    return np.clip(out, 0, 255).astype(np.uint8)


@functools.lru_cache(maxsize=8)
def _puddle_field(seed: int) -> tuple[NDArray[np.float32], NDArray[np.floating]]:
    """A town's static noise (two octaves of value noise on a 256-cell torus: puddles lie where
    they lie, as CARLA's) and its quantiles, to turn a share of the road into a threshold."""
    table = np.random.default_rng(seed).random((256, 256)).astype(np.float32)
    xy = np.random.default_rng(seed + 1).uniform(0, 256 * PUDDLE_CELL_M, (2, 20000))
    quantiles = np.quantile(_noise(table, xy[0], xy[1]), np.linspace(0, 1, 101))
    return table, quantiles


def _noise(table: NDArray[np.float32], x_m: Array, y_m: Array) -> NDArray[np.float32]:
    out: NDArray[np.float32] = np.zeros(np.shape(x_m), np.float32)
    for octave, weight in ((1.0, 0.7), (0.4, 0.3)):  # cells of 2.5 m and 1 m
        u, v = (
            np.asarray(x_m) / (PUDDLE_CELL_M * octave),
            np.asarray(y_m) / (PUDDLE_CELL_M * octave),
        )
        i, j = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        fu, fv = u - i, v - j
        fu, fv = fu * fu * (3 - 2 * fu), fv * fv * (3 - 2 * fv)  # smoothstep: no creases
        a, b = table[i % 256, j % 256], table[(i + 1) % 256, j % 256]
        c, d = table[i % 256, (j + 1) % 256], table[(i + 1) % 256, (j + 1) % 256]
        out += weight * ((a * (1 - fu) + b * fu) * (1 - fv) + (c * (1 - fu) + d * fu) * fv)
    return out


def puddle_mask(x_m: Array, y_m: Array, deposits: float, seed: int) -> NDArray[np.bool_]:
    """Where the road is under water (bool, the shape of ``x_m``): ``PUDDLE_MAX_SHARE *
    deposits`` of it, at the same places in every image of a town (``seed``)."""
    if deposits <= 0:
        return np.zeros(np.shape(x_m), bool)
    table, quantiles = _puddle_field(seed)
    share = min(1.0, PUDDLE_MAX_SHARE * deposits)
    threshold = np.interp(1 - share, np.linspace(0, 1, 101), quantiles)
    return _noise(table, x_m, y_m) > threshold


def apply_puddles(
    image: Image,
    depth_m: NDArray[np.float32],
    K: Array,
    world_from_cam: Array,
    deposits: float,
    seed: int,
    sky_rgb: Array,
    rng: np.random.Generator,
) -> Image:
    """Puddles on the road of an (H, W, 3) image: water darkens the road under it and mirrors the
    scene by Fresnel's share (Schlick, water's 2 % head-on, most at grazing angles).

    ``depth_m`` (H, W): each pixel's depth along the optical axis; ``K`` (3, 3) and
    ``world_from_cam`` (4, 4, OpenCV's optical frame) place it in the town. Computed at half
    resolution (reflections on rippled water are soft anyway): the mirror image is found by
    marching each reflected ray through the depth buffer (a screen-space reflection: what the
    camera does not see, such as the sky above the image, is the sky's ``sky_rgb`` (3,) in
    [0, 1]); rain ripples jitter it by a pixel or two (``rng``).
    """
    h, w = depth_m.shape
    hh, hw = h // 2, w // 2
    rot, centre = (
        world_from_cam[:3, :3].astype(np.float32),
        world_from_cam[:3, 3].astype(np.float32),
    )
    depth = depth_m[: 2 * hh : 2, : 2 * hw : 2]  # (hh, hw), pixel (2i, 2j) of the image
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    # where the road lies: pixels whose point is at road height (z = 0), in range
    rays_z = (np.arange(hh, dtype=np.float32) * 2 - cy) / fy  # optical y, per row
    rays_x = (np.arange(hw, dtype=np.float32) * 2 - cx) / fx
    world_z = centre[2] + depth * (
        rot[2, 0] * rays_x[None, :] + rot[2, 1] * rays_z[:, None] + rot[2, 2]
    )
    ys, xs = np.nonzero((np.abs(world_z) < PUDDLE_MAX_Z_M) & (depth < _MARCH_T_M[-1]))
    d = depth[ys, xs]
    cam_pts = np.stack([rays_x[xs] * d, rays_z[ys] * d, d], 1)
    p = centre + cam_pts @ rot.T  # (N, 3) road points
    wet = puddle_mask(p[:, 0], p[:, 1], deposits, seed)
    ys, xs, p = ys[wet], xs[wet], p[wet]
    if len(p) == 0:
        return image
    view = p - centre
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    mirrored = view * np.array([1.0, 1.0, -1.0], np.float32)
    # samples along each reflected ray, in the camera's frame: start + t * step, (M, S) each
    t = _MARCH_T_M.astype(np.float32)[None, :]
    start, step = (p - centre) @ rot, mirrored @ rot
    z = start[:, 2:] + t * step[:, 2:]
    front = z > 0.1
    zs = np.where(front, z, np.float32(1.0))
    ui = np.rint((fx * (start[:, :1] + t * step[:, :1]) / zs + cx) * 0.5)
    vi = np.rint((fy * (start[:, 1:2] + t * step[:, 1:2]) / zs + cy) * 0.5)
    inside = front & (ui >= 0) & (ui < hw) & (vi >= 0) & (vi < hh)
    ui = np.clip(ui, 0, hw - 1).astype(np.int32)
    vi = np.clip(vi, 0, hh - 1).astype(np.int32)
    scene_z = depth[vi, ui]
    # a hit: the sample passed behind what the camera sees there, but by no more than the last
    # step could have (a thin pole in front of the ray is not a wall), and on something
    # standing: a ray leaving flat water upwards never meets the road again (where it seems to,
    # near its start at grazing angles, that is the half-pixel rounding)
    hit = inside & (z > scene_z) & (z < scene_z + 0.5 + _MARCH_STEP_M[None, :])
    hit &= world_z[vi, ui] > PUDDLE_MAX_Z_M
    first = np.argmax(hit, axis=1)
    rows = np.arange(len(p))
    found = hit[rows, first]
    jitter = rng.integers(-2, 3, (2, len(p)))
    hu = np.clip(2 * (ui[rows, first] + jitter[0]), 0, w - 1)
    hv = np.clip(2 * (vi[rows, first] + jitter[1]), 0, h - 1)
    sky = np.asarray(sky_rgb, np.float32) * 255
    mirror = np.where(found[:, None], image[hv, hu].astype(np.float32), sky)
    fresnel = (0.02 + 0.98 * (1 - np.abs(view[:, 2])) ** 5)[:, None]
    # per 2x2 block of the image: its share of mirror and the mirrored colour
    share = np.zeros((hh, hw, 1), np.float32)
    mirrored_rgb = np.zeros((hh, hw, 3), np.float32)
    share[ys, xs], mirrored_rgb[ys, xs] = fresnel, mirror * fresnel
    share = np.repeat(np.repeat(share, 2, 0), 2, 1)
    mirrored_rgb = np.repeat(np.repeat(mirrored_rgb, 2, 0), 2, 1)
    out = image.copy()
    base = image[: 2 * hh, : 2 * hw]
    wet_px = share[..., 0] > 0
    # water over asphalt: darker, and a mirror
    under = base[wet_px] * (0.6 * (1 - share[wet_px])) + mirrored_rgb[wet_px]
    out[: 2 * hh, : 2 * hw][wet_px] = np.clip(under, 0, 255).astype(np.uint8)
    return out
