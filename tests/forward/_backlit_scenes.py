"""A back-lit scene for the transmission tests (issue 48): a dome seen from the front with
the key light behind it and to the right, the thickness growing from 1 mm at the key
light's terminator to 61 mm where the surface faces straight away from it, a fill light
from the front."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from invsss.forward.light_terms import LightBuffers
from tests.forward._lit_scenes import unit


def backlit_dome(size=32, seed=3, channels=1):
    """The source, depth, mask and buffers (normal, light, thickness, key_irradiance) of
    a textured dome lit from behind; RGB when ``channels`` is 3."""
    rng = np.random.default_rng(seed)
    texture = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, (size, size)), 1.5) * 2.0 + 0.3
    tints = np.array([1.0, 0.8, 0.6])[:channels]
    albedo = texture[..., None] * tints / 3.0
    y, x = (np.mgrid[0:size, 0:size] - (size - 1) / 2.0) / (size / 2.0)
    r2 = np.minimum(x**2 + y**2, 0.9)
    normal = unit(np.stack([0.9 * x, -0.9 * y, np.sqrt(1.0 - 0.81 * r2)], axis=-1))
    depth = 500.0 - 40.0 * np.sqrt(1.0 - 0.81 * r2)
    to_key = unit(np.array([0.5, 0.1, -0.86]))
    to_fill = unit(np.array([-0.3, 0.2, 0.93]))
    irradiance = 1.2 * (1.0 + 0.1 * x)  # a point light's fall-off across the dome
    key_irradiance = albedo * irradiance[..., None]
    key = key_irradiance * np.clip(normal @ to_key, 0.0, 1.0)[..., None]
    source = key + albedo * 0.5 * np.clip(normal @ to_fill, 0.0, 1.0)[..., None]
    facing = normal @ to_key
    # Thin near the terminator, thick deep on the far side, as for a head lit from behind.
    thickness = np.where(facing >= 0.0, 0.0, 1.0 + 60.0 * np.maximum(-facing, 0.0))
    mask = (x**2 + y**2 < 0.85).astype(float)
    light = np.broadcast_to(to_key, normal.shape).copy()
    buffers = LightBuffers(normal=normal, light=light, key=key, thickness=thickness, key_irradiance=key_irradiance)
    return source, depth, mask, buffers
