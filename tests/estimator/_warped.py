"""Warped images for the registration tests: a smooth texture, an inner mask, the texture
photographed through a known warp, and a model-made pair whose target is shifted."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

import invsss
from invsss.estimator.registration import Warp


def texture(size=96, seed=0):
    """A smooth random texture, (size, size, 1)."""
    rng = np.random.default_rng(seed)
    return 0.3 + ndimage.gaussian_filter(rng.uniform(size=(size, size)), 1.5)[..., None]


def inner_mask(size=96, border=14):
    """1 inside a border of ``border`` pixels, 0 on it."""
    mask = np.zeros((size, size))
    mask[border:-border, border:-border] = 1.0
    return mask


def photograph(image, warp):
    """``image`` seen through ``warp``: photo(warp(x)) = image(x), resampled exactly (cubic, order 5)."""
    inverse = np.linalg.inv(warp.matrix())
    c, t = np.asarray(warp.centre), np.asarray(warp.params[:2])
    # photo(y) = image(A^-1 (y - c - t) + c)
    offset = c - inverse @ (c + t)
    return np.stack([ndimage.affine_transform(image[..., k], inverse, offset=offset, order=5, mode="nearest")
                     for k in range(image.shape[-1])], axis=-1)


def shifted_pair():
    """Source, its render shifted by (1.4, -0.8) px as the target, depth and mask."""
    source = texture(80, seed=3)[..., 0]
    depth = np.full((80, 80), 500.0)
    mask = inner_mask(80, 12)
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [1.0], [1.0])
    clean = np.asarray(invsss.render(source, depth, mask, truth), np.float64)
    shifted = photograph(clean[..., None], Warp("translation", (1.4, -0.8), (39.5, 39.5)))[..., 0]
    return source, shifted, depth, mask
