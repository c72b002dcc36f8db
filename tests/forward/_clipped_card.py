"""A model-made card whose target is clipped at a level a fifth of its pixels reach, for
the saturation tests (kept in, the clipped pixels move sss_level by +38 %; left out,
-0.4 %)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

import invsss

SHAPE = (40, 48)
TRUTH = invsss.SSSParams(375.0, 0.0, 1.0, [0.3, 0.7], [1.0, 4.0])
PROFILE = {"weights": [0.5, 0.5], "variances": [1.0, 4.0]}
FIX = {"correction": 0.0, "maxdd": 1.0}


def clipped_card():
    """Source, clipped target, depth, mask and the clipping level."""
    rng = np.random.default_rng(2)
    source = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, SHAPE), 1.0) ** 3
    depth, mask = np.full(SHAPE, 500.0), np.ones(SHAPE)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH)) + 0.001 * rng.standard_normal(SHAPE)
    level = float(np.percentile(target, 80))
    return source, np.minimum(target, level), depth, mask, level
