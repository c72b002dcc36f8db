"""A small scene with renderer-style depth for the background-depth tests: a bump on a
500 mm plane, flat near the mask's edge, so that a background continuing the surface
flat is the unambiguous reference."""

from __future__ import annotations

import numpy as np

import invsss

H, W = 20, 24
PARAMS = invsss.SSSParams(600.0, 300.0, 0.02, [0.4, 0.6], [0.3, 1.5])


def scene():
    """Image, finite depth (a bump on a 500 mm plane, flat at the mask edge), mask."""
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r2 = ((x - 11.5) / 6.0) ** 2 + ((y - 9.5) / 5.0) ** 2
    depth = 500.0 - 25.0 * np.clip(1.0 - r2, 0.0, None) ** 2
    mask = np.zeros((H, W))
    mask[3:17, 4:20] = 1.0
    image = 0.2 + 0.6 * rng.random((H, W, 3))
    return image, depth, mask


def with_background(depth, mask, background):
    """``depth`` on the mask and ``background`` (0 or inf, as renderers write it) off it."""
    return np.where(mask > 0, depth, background)
