"""Synthetic scenes with known parameters for the estimator tests.

Each scene is a height field seen by a pinhole camera (depth in mm), a textured
albedo shaded by a directional light (the source image), a mask, and a target
rendered with the ``sog`` model at known parameters plus Gaussian noise of a
given fraction of the mean masked signal. Nothing here reads files.
"""

from __future__ import annotations

import jax
import numpy as np
from scipy.ndimage import gaussian_filter

import invsss


def _texture(rng, shape, channels, contrast=1.0):
    """Albedo with structure at every scale the blur probes (0.5 to 8 px)."""
    out = []
    for _ in range(channels):
        fine = gaussian_filter(rng.standard_normal(shape), 0.6)
        mid = gaussian_filter(rng.standard_normal(shape), 2.0)
        coarse = gaussian_filter(rng.standard_normal(shape), 6.0)
        t = 0.5 + contrast * (0.15 * fine / fine.std() + 0.08 * mid / mid.std()) + 0.1 * coarse / coarse.std()
        out.append(np.clip(t, 0.02, None))
    return np.stack(out, axis=-1)


def _shade(depth):
    """Lambertian shading of the height field under a light from the upper left."""
    gy, gx = np.gradient(depth)
    normal = np.stack([gx, gy, -np.ones_like(depth)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    light = np.array([-0.4, -0.5, -0.77])
    light /= np.linalg.norm(light)
    return np.clip(normal @ light, 0.05, None)


def face_depth(size=64):
    """An ellipsoidal head with a nose, brows and cheeks; mask inside the silhouette."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    cy, cx = (size - 1) / 2, (size - 1) / 2
    a, b = 0.46 * size, 0.49 * size
    u, v = (x - cx) / a, (y - cy) / b
    inside = np.clip(1.0 - u**2 - v**2, 0.0, None)
    relief = 90.0 * np.sqrt(inside)
    bumps = (
        14.0 * np.exp(-((x - cx) ** 2 / (2 * 3.0**2) + (y - cy - 2) ** 2 / (2 * 5.0**2)))
        + 5.0 * np.exp(-((x - cx - 10) ** 2 + (y - cy - 6) ** 2) / (2 * 5.0**2))
        + 5.0 * np.exp(-((x - cx + 10) ** 2 + (y - cy - 6) ** 2) / (2 * 5.0**2))
        + 4.0 * np.exp(-((y - cy + 9) ** 2) / (2 * 2.0**2)) * (np.abs(x - cx) < 12)
    )
    depth = 650.0 - relief - bumps * (inside > 0)
    mask = (u**2 + v**2 < 0.86**2).astype(np.float64)
    return depth, mask


def wave_depth(size=64):
    """A tilted plane with crossed sinusoidal ripples; mask is a rounded square."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    depth = 500.0 + 0.9 * x + 7.0 * np.sin(x / 4.0 + 0.3) + 9.0 * np.cos(y / 5.0 - 0.7) * (1 + 0.02 * y)
    c = (size - 1) / 2
    mask = ((np.abs(x - c) ** 4 + np.abs(y - c) ** 4) < (0.44 * size) ** 4).astype(np.float64)
    return depth, mask


def flat_depth(size=64):
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    c = (size - 1) / 2
    mask = ((x - c) ** 2 + (y - c) ** 2 < (0.45 * size) ** 2).astype(np.float64)
    return np.full((size, size), 600.0), mask


SCENES = {"face": face_depth, "wave": wave_depth, "flat": flat_depth}


def make_pair(scene, params, *, size=64, source_channels=1, target="same", noise=0.01, seed=0,
              mix=(0.5, 0.3, 0.2), gain=0.8, offset=0.05, shift=(0, 0), model="sog", contrast=1.0):
    """(source, target, depth, mask) and the noiseless target for ``params``.

    ``target``: "same" renders every source channel, "grey" mixes an RGB source to
    one channel with ``mix`` before rendering (the blur commutes with the mix).
    ``shift`` rolls the target by (dy, dx) pixels to simulate a misaligned pair.
    """
    rng = np.random.default_rng(seed)
    depth, mask = SCENES[scene](size)
    source = _texture(rng, depth.shape, source_channels, contrast) * _shade(depth)[..., None]
    image = source
    if target == "grey":
        image = source @ np.asarray(mix)[:, None]
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(image, depth, mask, params, model))
    clean = gain * clean + offset
    sigma = noise * float(np.mean(clean[mask > 0]))
    noisy = clean + sigma * rng.standard_normal(clean.shape)
    if shift != (0, 0):
        noisy = np.roll(noisy, shift, axis=(0, 1))
    return source, noisy, depth, mask, clean


def textured_pair(size, level, variance, seed=0):
    """A textured source at 500 mm blurred by one Gaussian of ``variance`` mm^2 (sog)."""
    rng = np.random.default_rng(seed)
    source = np.clip(0.5 + 0.25 * gaussian_filter(rng.standard_normal((size, size, 1)), (1.0, 1.0, 0)) / 0.14,
                     0.05, None)
    depth = np.full((size, size), 500.0)
    mask = np.ones((size, size))
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(source, depth, mask, invsss.SSSParams(level, 0.0, 1.0, [1.0], [variance])))
    target = clean + 0.003 * rng.standard_normal(clean.shape)
    return source, target, depth, mask
