"""Rain as an image post-process: streaks, drops on the lens, a veil of spray, sensor noise.

Deterministic for a given ``rng``. Costs about 25 ms at 800x600.
"""

from __future__ import annotations

import cv2
import numpy as np

from vlocbench.interfaces import Image


def apply_rain(image: Image, amount: float, brightness: float, rng: np.random.Generator) -> Image:
    """Rain of strength ``amount`` in [0, 1] on an (H, W, 3) image; ``brightness`` in [0, 1] of the sky."""
    if amount <= 0:
        return image
    h, w = image.shape[:2]
    out = image.astype(np.float32)
    # veil: spray and scattering lower the contrast towards a grey
    veil = 255 * (0.55 * brightness + 0.05)
    out = out * (1 - 0.25 * amount) + veil * 0.25 * amount
    # streaks: short slanted bright lines, blurred along their direction
    layer = np.zeros((h, w), np.float32)
    n = int(amount * 0.0012 * h * w)
    xs, ys = rng.integers(0, w, n), rng.integers(0, h, n)
    lengths = rng.integers(h // 40, h // 12, n)
    slant = rng.normal(0.15, 0.03)
    for x, y, length in zip(xs, ys, lengths):
        cv2.line(layer, (int(x), int(y)), (int(x + slant * length), int(y + length)), 1.0, 1)
    layer = cv2.GaussianBlur(layer, (3, 3), 0)
    out += layer[..., None] * 255 * (0.25 + 0.35 * brightness)
    # drops on the lens: blurred, slightly brighter discs
    for _ in range(int(amount * 14)):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        r = int(rng.integers(h // 60, h // 25))
        x0, x1, y0, y1 = max(0, x - r), min(w, x + r), max(0, y - r), min(h, y + r)
        patch = out[y0:y1, x0:x1]
        blurred = cv2.GaussianBlur(patch, (0, 0), r / 2)
        mask = np.zeros(patch.shape[:2], np.float32)
        cv2.circle(mask, (x - x0, y - y0), r, 1.0, -1)
        mask = cv2.GaussianBlur(mask, (0, 0), max(1, r / 4))[..., None]
        out[y0:y1, x0:x1] = patch * (1 - mask) + (blurred * 1.05 + 6) * mask
    out += rng.normal(0, 2 + 3 * amount, (h, w, 1))
    return np.clip(out, 0, 255).astype(np.uint8)
