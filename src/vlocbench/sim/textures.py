"""Procedural textures (uint8 RGB arrays, (H, W, 3), row 0 at the top) drawn with OpenCV.

Facades are atlases of one-bay x one-floor window cells; ground floors carry shop windows, doors
and signs with text. Everything is a pure function of its arguments and an explicit ``numpy`` Generator, so a
town's textures are as deterministic as its layout.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from vlocbench.interfaces import Image

PX_PER_M = 64  # texel density of facade tiles: about 1.3 texels per pixel at 5 m with fx = 400

_SHOP_WORDS = (
    "CAFE",
    "BAKERY",
    "BOOKS",
    "PHARMACY",
    "HOTEL",
    "BAR",
    "PIZZA",
    "BANK",
    "FLOWERS",
    "SHOES",
    "MARKET",
    "DELI",
    "OPTICS",
    "SUSHI",
    "TAILOR",
    "TOYS",
    "GARAGE",
    "KEBAB",
    "RADIO",
    "CINEMA",
)
_SHOP_NAMES = (
    "ROMA",
    "NORD",
    "LUNA",
    "ATLAS",
    "MILANO",
    "OSLO",
    "EDEN",
    "ORION",
    "KAPPA",
    "SOL",
    "ALBA",
    "VEGA",
    "DELTA",
    "LIDO",
    "POLO",
    "AURA",
)


def noise(shape: tuple[int, int], rng: np.random.Generator, scale_px: int, amp: float) -> NDArray:
    """Smooth value noise in [-amp, amp], (H, W) float32."""
    h, w = shape
    small = rng.uniform(-1, 1, (max(2, h // scale_px + 2), max(2, w // scale_px + 2)))
    return cv2.resize(small.astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC) * amp


def _finish(img: NDArray, rng: np.random.Generator, grain: float = 6.0) -> Image:
    img = img.astype(np.float32) + rng.normal(0, grain, img.shape[:2])[..., None]
    return np.clip(img, 0, 255).astype(np.uint8)


def _rgb(color: tuple[float, float, float] | NDArray) -> tuple[int, int, int]:
    # OpenCV draws in the array's channel order; our arrays are RGB
    return tuple(int(c) for c in color)  # type: ignore[return-value]


@dataclass(frozen=True)
class FacadeTile:
    """A facade texture: ``variants`` cells side by side, each covering ``width_m`` x ``height_m``."""

    image: Image
    width_m: float
    height_m: float
    variants: int = 1
    # the window of every cell as shares of the cell: left, top, right, bottom (from its top-left)
    window: tuple[float, float, float, float] | None = None
    recess_m: float = 0.0  # how far the window sits behind the wall's face (0: a flat wall)


FACADE_VARIANTS = 12  # window cells per facade style; every wall draws its own sequence of them
# masonry windows sit this far behind the wall's face (glass curtain walls are flat): CARLA's
# facades have such relief, and a flat wall leaves PnP two poses as good as each other
WINDOW_RECESS_M = 0.2


@dataclass(frozen=True)
class _FacadeStyle:
    """What the cells of one facade style share (sizes in texels, colours RGB 0-255)."""

    family: int  # 0 brick, 1 plaster, 2 stone, 3 concrete panels, 4 glass curtain wall
    size: tuple[int, int]  # cell (height, width)
    base: NDArray
    window: tuple[int, int, int, int]  # x0, y0, x1, y1
    frame: NDArray
    glass: NDArray
    balconies: bool
    shutter_color: NDArray | None


LIT_WINDOW_RGB = (255, 217, 153)  # a warm interior light
LIT_WINDOW_TEXELS = 256


def lit_windows(share: float) -> Image:
    """The lit windows' texture, (4, LIT_WINDOW_TEXELS, 3): a window whose rank (its texture
    coordinate u, uniform in [0, 1)) is below ``share`` is lit, the others are black (unlit glass
    at night)."""
    image = np.zeros((4, LIT_WINDOW_TEXELS, 3), np.uint8)
    image[:, : round(share * LIT_WINDOW_TEXELS)] = LIT_WINDOW_RGB
    return image


def facade(
    style: int, floor_height_m: float, rng: np.random.Generator, variants: int = FACADE_VARIANTS
) -> FacadeTile:
    """One facade style as ``variants`` one-bay x one-floor cells of brick, plaster, stone or glass.

    The style (material, colours, bay width, window shape) is shared by its cells; curtains, panes,
    blinds, plants, stains and pipes differ from cell to cell, so that a wall laid out from random
    cells repeats neither along itself nor across the buildings of the same style.
    """
    family = style % 5
    bay_m = float(rng.uniform(3.0, 4.2))
    w, h = round(bay_m * PX_PER_M), round(floor_height_m * PX_PER_M)
    base = np.array(
        [
            rng.uniform([150, 70, 50], [190, 100, 75]),  # brick
            rng.uniform([190, 170, 140], [235, 215, 190]),  # plaster
            rng.uniform([150, 145, 135], [190, 185, 175]),  # stone
            rng.uniform([120, 125, 130], [160, 165, 170]),  # concrete panels
            rng.uniform([60, 80, 100], [90, 115, 140]),  # glass curtain wall
        ][family]
    )
    win_w = float(rng.uniform(0.35, 0.6)) * bay_m
    win_h = float(rng.uniform(0.45, 0.62)) * floor_height_m
    if family == 4:  # glass: a full-height panel with mullions
        window = (3, 6, w - 3, h - 10)
    else:
        y0 = round((floor_height_m - win_h) * 0.45 * PX_PER_M)
        window = (
            round((w - win_w * PX_PER_M) / 2),
            y0,
            round((w + win_w * PX_PER_M) / 2),
            round(y0 + win_h * PX_PER_M),
        )
    frame = rng.uniform(20, 240, 3)
    glass = rng.uniform([40, 55, 70], [90, 110, 130])
    balconies = family in (1, 2) and rng.random() < 0.5
    shutter_color = rng.uniform(40, 200, 3) if family in (0, 1) and rng.random() < 0.4 else None
    look = _FacadeStyle(family, (h, w), base, window, frame, glass, balconies, shutter_color)
    cells = [_facade_cell(look, rng) for _ in range(variants)]
    x0, y0, x1, y1 = window
    share = (x0 / w, y0 / h, x1 / w, y1 / h)
    recess_m = 0.0 if family == 4 else WINDOW_RECESS_M
    return FacadeTile(atlas(cells, variants), bay_m, floor_height_m, variants, share, recess_m)


def _facade_cell(look: _FacadeStyle, rng: np.random.Generator) -> Image:
    """One bay of one floor in ``look``, with its own window dressing and weathering."""
    (h, w), base, family = look.size, look.base, look.family
    x0, y0, x1, y1 = look.window
    img = np.ones((h, w, 3), np.float32) * base
    img += noise((h, w), rng, 24, 14)[..., None]
    _wall_pattern(img, family, base, rng)
    _window(img, look.window, look.glass, look.frame, rng)
    if family != 4:
        cv2.rectangle(img, (x0 - 4, y1), (x1 + 4, y1 + 6), _rgb(base * 0.6 + 60), -1)
        if rng.random() < 0.2:  # flower box on the sill
            cv2.rectangle(img, (x0, y1 - 10), (x1, y1), _rgb(rng.uniform(60, 160, 3)), -1)
            for xx in range(x0 + 4, x1 - 4, 9):
                leaf = rng.uniform([30, 90, 20], [90, 170, 70])
                cv2.circle(img, (xx, y1 - 12), int(rng.integers(3, 7)), _rgb(leaf), -1)
        if rng.random() < 0.12:  # air conditioner under the window
            ax = int(rng.integers(x0, max(x0 + 1, x1 - 40)))
            cv2.rectangle(img, (ax, y1 + 10), (ax + 40, y1 + 34), (205, 205, 200), -1)
            cv2.circle(img, (ax + 20, y1 + 22), 8, (120, 120, 120), 1)
    if look.shutter_color is not None:
        sw = (x1 - x0) // 3
        for sx in (x0 - sw - 2, x1 + 2):
            cv2.rectangle(img, (sx, y0), (sx + sw, y1), _rgb(look.shutter_color), -1)
            for yy in range(y0, y1, 6):
                cv2.line(img, (sx, yy), (sx + sw, yy), _rgb(look.shutter_color * 0.7), 1)
    if look.balconies and rng.random() < 0.5:
        railing = _rgb(look.frame * 0.5)
        cv2.rectangle(img, (x0 - 12, y1 - 28), (x1 + 12, y1 + 2), railing, 2)
        for xx in range(x0 - 12, x1 + 12, 8):
            cv2.line(img, (xx, y1 - 28), (xx, y1 + 2), railing, 1)
    if family == 4:
        img = cv2.GaussianBlur(img, (3, 3), 0)
    else:
        _weathering(img, rng, base)
    return _finish(img, rng)


def _wall_pattern(img: NDArray, family: int, base: NDArray, rng: np.random.Generator) -> None:
    """Brick courses or stone/panel joints over a cell (in place)."""
    h, w = img.shape[:2]
    if family == 0:
        course = max(4, PX_PER_M // 13)
        for row, y in enumerate(range(0, h, course)):
            cv2.line(img, (0, y), (w, y), _rgb(base * 0.7), 1)
            off = (row % 2) * course * 2
            for x in range(off, w, course * 4):
                cv2.line(img, (x, y), (x, y + course), _rgb(base * 0.72), 1)
        img += (
            rng.normal(0, 10, (h // course + 1, w // (course * 2) + 1))
            .repeat(course, 0)
            .repeat(course * 2, 1)[:h, :w, None]
        )
    elif family in (2, 3):  # stone blocks (3 courses a floor) / one concrete panel a cell
        rows, cols = (3, 2) if family == 2 else (1, 1)
        for y in range(0, h, h // rows):
            cv2.line(img, (0, y), (w, y), _rgb(base * 0.75), 2)
        for x in range(0, w, w // cols):
            cv2.line(img, (x, 0), (x, h), _rgb(base * 0.78), 2)
    if family == 3:
        # exposed aggregate, a blotchy grain of a few centimetres: smooth panels in the shade gave
        # the paper's SIFT 35-80 keypoints a view where other walls give 200-450 (105-180 with
        # the grain), and town01's noon failures sat in front of them
        # (drawn from a spawned generator: every other texture of the town stays as it was)
        img += noise((h, w), rng.spawn(1)[0], 4, 40)[..., None]


def _window(
    img: NDArray,
    box: tuple[int, int, int, int],
    glass: NDArray,
    frame: NDArray,
    rng: np.random.Generator,
) -> None:
    """A framed window with this cell's own pane shade, curtains and blinds (in place)."""
    x0, y0, x1, y1 = box
    pane = glass + rng.uniform(-15, 25)
    img[y0:y1, x0:x1] = pane * np.linspace(1.25, 0.8, max(1, y1 - y0))[:, None, None]
    if rng.random() < 0.6:  # curtains, on one side or both
        cw = round((x1 - x0) * rng.uniform(0.15, 0.4))
        color = rng.uniform(120, 230, 3)
        side = rng.integers(0, 3)
        if side != 1:
            img[y0:y1, x0 : x0 + cw] = color
        if side != 0:
            img[y0:y1, x1 - cw : x1] = color
    if rng.random() < 0.3:  # blinds pulled part way down
        yb = y0 + round((y1 - y0) * rng.uniform(0.2, 0.8))
        img[y0:yb, x0:x1] = rng.uniform(170, 235)
        for yy in range(y0, yb, 5):
            cv2.line(img, (x0, yy), (x1, yy), _rgb(np.full(3, 140.0)), 1)
    cv2.rectangle(img, (x0, y0), (x1, y1), _rgb(frame), 3)
    cv2.line(img, ((x0 + x1) // 2, y0), ((x0 + x1) // 2, y1), _rgb(frame), 2)
    cv2.line(img, (x0, (y0 + y1) // 2), (x1, (y0 + y1) // 2), _rgb(frame), 2)


def _weathering(img: NDArray, rng: np.random.Generator, base: NDArray) -> None:
    """Stains, patches and now and then a drainpipe: the irregular detail real walls have."""
    h, w = img.shape[:2]
    for _ in range(int(rng.integers(6, 14))):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        axes = (int(rng.integers(3, 14)), int(rng.integers(3, 14)))
        shade = base * float(rng.uniform(0.6, 1.25))
        cv2.ellipse(img, (x, y), axes, float(rng.uniform(0, 180)), 0, 360, _rgb(shade), -1)
    if rng.random() < 0.15:
        x = int(rng.integers(6, w - 6))
        cv2.line(img, (x, 0), (x, h), _rgb(base * 0.5), 5)
        for y in range(int(rng.integers(0, 40)), h, 90):
            cv2.rectangle(img, (x - 6, y), (x + 6, y + 6), _rgb(base * 0.4), -1)


SHOP_WIDTH_M = 7.0  # every shopfront tile covers this much wall (they share one atlas)


def shopfront(style: int, height_m: float, rng: np.random.Generator) -> FacadeTile:
    """Ground-floor tile: a shop window, a door and a sign band with the shop's name."""
    width_m = SHOP_WIDTH_M
    w, h = round(width_m * PX_PER_M), round(height_m * PX_PER_M)
    wall = rng.uniform(60, 200, 3)
    img = np.ones((h, w, 3), np.float32) * wall + noise((h, w), rng, 20, 10)[..., None]
    img = np.clip(img, 0, 255).astype(np.uint8)  # putText draws on 8-bit images only
    band = rng.uniform(20, 230, 3)
    band_h = round(0.7 * PX_PER_M)
    cv2.rectangle(img, (0, 0), (w, band_h), _rgb(band), -1)
    text = f"{_SHOP_WORDS[(style * 7 + int(rng.integers(0, 3))) % len(_SHOP_WORDS)]} "
    text += _SHOP_NAMES[int(rng.integers(0, len(_SHOP_NAMES)))]
    lum = band @ np.array([0.3, 0.59, 0.11])
    ink = (20, 20, 20) if lum > 128 else (245, 240, 230)
    scale = 1.6 * PX_PER_M / 64
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_DUPLEX, scale, 3)
    scale *= min(1.0, 0.9 * w / tw)
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_DUPLEX, scale, 3)
    cv2.putText(
        img,
        text,
        ((w - tw) // 2, (band_h + th) // 2),
        cv2.FONT_HERSHEY_DUPLEX,
        scale,
        ink,
        3,
        cv2.LINE_AA,
    )
    # awning stripes under the band
    stripe = rng.uniform(40, 240, 3)
    for k, x in enumerate(range(0, w, 24)):
        cv2.rectangle(
            img, (x, band_h), (x + 24, band_h + 24), _rgb(stripe if k % 2 else (240,) * 3), -1
        )
    top = band_h + 40
    door_w = round(1.1 * PX_PER_M)
    door_x = round(rng.uniform(0.05, 0.2) * w)
    cv2.rectangle(img, (door_x, top), (door_x + door_w, h), _rgb(rng.uniform(30, 120, 3)), -1)
    cv2.rectangle(img, (door_x + 8, top + 10), (door_x + door_w - 8, h - 40), (70, 85, 95), -1)
    cv2.circle(img, (door_x + door_w - 18, (top + h) // 2), 5, (200, 190, 120), -1)
    wx0, wx1 = door_x + door_w + 20, w - 16
    window = rng.uniform([50, 60, 70], [100, 110, 120])
    img[top + 8 : h - 30, wx0:wx1] = window * np.linspace(1.3, 0.8, h - 38 - top)[:, None, None]
    # goods in the window
    for _ in range(int(rng.integers(4, 10))):
        gx = int(rng.integers(wx0 + 5, max(wx0 + 6, wx1 - 30)))
        gy = int(rng.integers(top + 40, max(top + 41, h - 60)))
        cv2.rectangle(img, (gx, gy), (gx + 25, gy + 30), _rgb(rng.uniform(30, 250, 3)), -1)
    cv2.rectangle(img, (wx0, top + 8), (wx1, h - 30), _rgb(band * 0.6), 4)
    img[h - 30 :] = wall * 0.7
    return FacadeTile(_finish(img.astype(np.float32), rng), width_m, height_m)


def asphalt(size: int, rng: np.random.Generator, base: float = 85.0) -> NDArray:
    img = np.ones((size, size, 3), np.float32) * base + noise((size, size), rng, 16, 10)[..., None]
    img += rng.normal(0, 9, (size, size))[..., None]
    return img


def road_tile(
    lane_width_m: float, length_m: float, rng: np.random.Generator, lanes_per_direction: int = 1
) -> Image:
    """Road texture across all lanes (u: across, 0 = right curb) and ``length_m`` along (v): a
    dashed yellow centre line, dashed white lines between lanes of one direction, white edges."""
    px = 24  # texels per metre
    w, h = round(2 * lanes_per_direction * lane_width_m * px), round(length_m * px)
    img = asphalt(max(w, h), rng)[:h, :w]
    for _ in range(6 * lanes_per_direction):  # patches and cracks
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        cv2.ellipse(
            img,
            (x, y),
            (int(rng.integers(8, 40)), int(rng.integers(8, 60))),
            0,
            0,
            360,
            _rgb((70, 70, 72)),
            -1,
        )
    cx = w // 2
    dash = round(3 * px)
    for y in range(0, h, round(length_m * px / 2)):
        cv2.rectangle(img, (cx - 3, y), (cx + 3, y + dash), (225, 215, 170), -1)
        for k in range(1, lanes_per_direction):
            for x in (cx - round(k * lane_width_m * px), cx + round(k * lane_width_m * px)):
                cv2.rectangle(img, (x - 2, y), (x + 2, y + dash), (220, 220, 215), -1)
    edge = round(0.35 * px)
    cv2.rectangle(img, (edge, 0), (edge + 4, h), (220, 220, 215), -1)
    cv2.rectangle(img, (w - edge - 4, 0), (w - edge, h), (220, 220, 215), -1)
    return _finish(img, rng, 4)


def crosswalk_tile(rng: np.random.Generator) -> Image:
    img = asphalt(128, rng)
    for x in range(8, 128, 32):
        img[:, x : x + 16] = np.clip(img[:, x : x + 16] + 140, 0, 235)
    return _finish(img, rng, 4)


PAVING_TILE_M = 16.0  # the paving texture's tile (the scene lays it in shifted blocks)
PAVING_SLAB_M = 0.5


def paving(rng: np.random.Generator, snow: float = 0.0) -> Image:
    """Sidewalk slabs of ``PAVING_SLAB_M`` over a 16 m x 16 m tile, optionally covered by snow in [0, 1].

    Every slab has its own shade and few, faint spots: a short-period, high-contrast pattern
    would be the same everywhere in town, and a localizer would match the ground of one street
    to the ground of another. No grout lines: their crossings, a dark cross on light stone every
    0.5 m, all look alike, and a map matched one crossing to another along the cameras' epipolar
    lines (a right-facing camera's run along the rows of slabs) and triangulated them into ghost
    points off every surface: 36 % of town01's map points, which cost `sift` 5 points of T1
    recall at noon (docs/reproduction.md).
    """
    px_per_m = 64
    size = round(PAVING_TILE_M * px_per_m)
    base = rng.uniform(165, 195)
    img = np.ones((size, size, 3), np.float32) * np.array([base, base * 0.97, base * 0.92])
    img += noise((size, size), rng, 24, 8)[..., None]
    slab = round(PAVING_SLAB_M * px_per_m)
    shades = rng.uniform(0.9, 1.08, (size // slab, size // slab))
    img *= np.kron(shades, np.ones((slab, slab)))[..., None]
    for _ in range(400):  # pebbles and chewing gum
        x, y = rng.integers(0, size, 2)
        shade = (base * rng.uniform(0.6, 1.15),) * 3
        cv2.circle(img, (int(x), int(y)), int(rng.integers(1, 4)), _rgb(shade), -1)
    return _snow(_finish(img, rng), rng, snow)


# grass covers the parks and the town's open ground: laid as a 4 m tile, its repeats gave the maps
# ghost points behind every park (docs/reproduction.md); the other kinds stay 4 m
GROUND_TILE_M = {"grass": 16.0, "autumn_grass": 16.0}


def ground_tile_m(kind: str) -> float:
    """The side of ``kind``'s ground tile (m)."""
    return GROUND_TILE_M.get(kind, 4.0)


def ground(kind: str, rng: np.random.Generator, snow: float = 0.0) -> Image:
    """A tile of grass, sand, water, roof gravel, bark, leaves or concrete of 64 px a metre over
    :func:`ground_tile_m` (grass 16 m, the others 4 m; the scene stretches water's over 8 m)."""
    size = round(64 * ground_tile_m(kind))
    colors = {
        "grass": (75, 120, 50),
        "autumn_grass": (120, 115, 60),
        "sand": (215, 200, 155),
        "water": (50, 95, 130),
        "roof": (95, 92, 90),
        "bark": (85, 65, 45),
        "leaves": (200, 200, 200),  # tinted by the material colour (season)
        "concrete": (170, 168, 160),
        "metal": (90, 95, 100),
    }
    img = np.ones((size, size, 3), np.float32) * np.array(colors[kind], np.float32)
    amp = {"water": 8, "leaves": 45, "grass": 22}.get(kind, 16)
    img += noise((size, size), rng, 8, amp)[..., None]
    img += noise((size, size), rng, 40, amp)[..., None]
    if kind == "leaves":
        for _ in range(900):
            x, y = rng.integers(0, size, 2)
            cv2.circle(
                img, (int(x), int(y)), int(rng.integers(2, 6)), _rgb(rng.uniform(90, 255, 3)), -1
            )
    return _snow(_finish(img, rng, 8), rng, snow)


def _snow(img: Image, rng: np.random.Generator, amount: float) -> Image:
    if amount <= 0:
        return img
    h, w = img.shape[:2]
    cover = np.clip(noise((h, w), rng, 10, 1.0) * 0.5 + amount, 0, 1)[..., None]
    white = np.array([235, 238, 245], np.float32) + rng.normal(0, 6, (h, w))[..., None]
    return np.clip(img * (1 - cover) + white * cover, 0, 255).astype(np.uint8)


def snowy_road(road: Image, rng: np.random.Generator) -> Image:
    """Winter road: snow along both edges, tyre tracks clear in each lane."""
    h, w = road.shape[:2]
    u = np.abs(np.linspace(-1, 1, w))
    edge = np.clip((u - 0.7) / 0.25, 0, 1)
    cover = np.clip(edge[None, :] + noise((h, w), rng, 12, 0.25), 0, 1)[..., None]
    white = np.array([225, 228, 235], np.float32)
    return np.clip(road * (1 - cover) + white * cover, 0, 255).astype(np.uint8)


def sign_atlas(rng: np.random.Generator) -> Image:
    """Eight traffic signs in a 4x2 atlas of 128 px cells (stop, yield, speed limits, ...)."""
    cell = 128
    img = np.full((2 * cell, 4 * cell, 3), 200, np.uint8)
    for k in range(8):
        cx, cy = (k % 4) * cell + cell // 2, (k // 4) * cell + cell // 2
        if k == 0:  # stop
            pts = [
                (cx + 56 * np.cos(a), cy + 56 * np.sin(a))
                for a in np.arange(8) * np.pi / 4 + np.pi / 8
            ]
            cv2.fillPoly(img, [np.array(pts, np.int32)], (200, 20, 25))
            cv2.putText(
                img, "STOP", (cx - 44, cy + 12), cv2.FONT_HERSHEY_DUPLEX, 1.1, (250,) * 3, 2
            )
        elif k == 1:  # yield
            pts = [(cx - 56, cy - 48), (cx + 56, cy - 48), (cx, cy + 52)]
            cv2.fillPoly(img, [np.array(pts, np.int32)], (200, 20, 25))
            cv2.fillPoly(
                img,
                [np.array([(cx - 34, cy - 34), (cx + 34, cy - 34), (cx, cy + 26)], np.int32)],
                (250,) * 3,
            )
        elif k in (2, 3, 4):  # speed limits
            cv2.circle(img, (cx, cy), 58, (200, 20, 25), -1)
            cv2.circle(img, (cx, cy), 44, (250, 250, 250), -1)
            cv2.putText(
                img,
                str((k - 1) * 20 + 10),
                (cx - 30, cy + 15),
                cv2.FONT_HERSHEY_DUPLEX,
                1.3,
                (20, 20, 20),
                3,
            )
        elif k == 5:  # no entry
            cv2.circle(img, (cx, cy), 58, (200, 20, 25), -1)
            cv2.rectangle(img, (cx - 40, cy - 10), (cx + 40, cy + 10), (250, 250, 250), -1)
        elif k == 6:  # pedestrian crossing
            cv2.rectangle(img, (cx - 56, cy - 56), (cx + 56, cy + 56), (30, 80, 200), -1)
            cv2.fillPoly(
                img,
                [np.array([(cx - 40, cy + 40), (cx + 40, cy + 40), (cx, cy - 44)], np.int32)],
                (250,) * 3,
            )
            cv2.circle(img, (cx, cy - 8), 8, (20, 20, 20), -1)
            cv2.line(img, (cx, cy), (cx - 10, cy + 30), (20, 20, 20), 4)
        else:  # street name plate
            cv2.rectangle(img, (cx - 60, cy - 30), (cx + 60, cy + 30), (20, 90, 40), -1)
            name = _SHOP_NAMES[int(rng.integers(0, len(_SHOP_NAMES)))][:6]
            cv2.putText(img, name, (cx - 54, cy + 12), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (250,) * 3, 2)
    return img


def sky(
    zenith_rgb: tuple[float, float, float],
    horizon_rgb: tuple[float, float, float],
    size: int = 64,
) -> Image:
    """A MuJoCo cube-map skybox (6 faces of ``size`` x ``size`` stacked: (6*size, size, 3)).

    Side faces fade from horizon (bottom rows) to zenith (top rows); +z is the zenith colour and
    -z the horizon colour. Colours in [0, 1].
    """
    zen = np.array(zenith_rgb, np.float32) * 255
    hor = np.array(horizon_rgb, np.float32) * 255
    t = np.linspace(0, 1, size, dtype=np.float32)[:, None, None] ** 0.6
    side = np.broadcast_to(zen * (1 - t) + hor * t, (size, size, 3))
    faces = [
        side,
        side,
        side,
        side,
        np.broadcast_to(zen, (size, size, 3)),
        np.broadcast_to(hor, (size, size, 3)),
    ]
    return np.clip(np.concatenate(faces, axis=0), 0, 255).astype(np.uint8)


def atlas(tiles: list[Image], columns: int) -> Image:
    """Equal-sized tiles in a grid, row by row from the top left."""
    h, w = tiles[0].shape[:2]
    rows = -(-len(tiles) // columns)
    out = np.zeros((rows * h, columns * w, 3), np.uint8)
    for k, tile in enumerate(tiles):
        r, c = divmod(k, columns)
        out[r * h : (r + 1) * h, c * w : (c + 1) * w] = tile
    return out
