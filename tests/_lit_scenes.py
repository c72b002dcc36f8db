"""A model-made lit pair for the light-term tests: a textured dome under a key and a
fill light, with the key light's part of the source and the normal and light buffers."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

import invsss
from invsss.forward.light_terms import LightBuffers


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def dome_with_two_lights(size=40, seed=2):
    """A textured dome lit by a key light from the upper left and a weaker fill
    from the right, RGB: the source, the key light's part, and the buffers (the
    fill's direction too)."""
    rng = np.random.default_rng(seed)
    texture = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, (size, size)), 1.5) * 2.0 + 0.3
    texture[:, 14:17] *= 0.3
    albedo = np.stack([texture, 0.8 * texture, 0.6 * texture], axis=-1) / 3.0
    y, x = (np.mgrid[0:size, 0:size] - (size - 1) / 2.0) / (size / 2.0)
    r2 = np.minimum(x**2 + y**2, 0.9)
    normal = _unit(np.stack([0.9 * x, -0.9 * y, np.sqrt(1.0 - 0.81 * r2)], axis=-1))
    depth = 500.0 - 40.0 * np.sqrt(1.0 - 0.81 * r2)
    to_key = _unit(np.array([-0.6, 0.3, 0.74]))
    to_fill = _unit(np.array([0.5, 0.2, 0.84]))
    key = albedo * 0.9 * np.clip(normal @ to_key, 0.0, 1.0)[..., None]
    source = key + albedo * 0.4 * np.clip(normal @ to_fill, 0.0, 1.0)[..., None]
    light = np.broadcast_to(to_key, normal.shape).copy()
    fill_light = np.broadcast_to(to_fill, normal.shape).copy()
    mask = (x**2 + y**2 < 0.85).astype(float)
    return source, depth, mask, LightBuffers(normal=normal, light=light, key=key, fill_light=fill_light)


PROFILE = {"weights": [0.5, 0.5], "variances": [0.5, 2.0]}
FIX = {"correction": 0.0, "maxdd": 1.0}
TRUTH = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])


def lit_target(source, depth, mask, buffers, terms, noise=0.002):
    target = np.asarray(invsss.render(source, depth, mask, TRUTH, light_terms=terms, light_buffers=buffers))
    return target + np.random.default_rng(1).normal(0.0, noise, target.shape)
