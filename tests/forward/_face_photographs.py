"""A model-made pair of photographs at one depth (a textured disc on black, a face on a
dark background), for the tests of pairs made from two photographs."""

from __future__ import annotations

import jax
import numpy as np
from scipy.ndimage import gaussian_filter

import invsss

SIZE = 44
PROFILE = {"weights": [0.5, 0.5], "variances": [0.6, 3.0]}
TRUTH_LEVEL = 600.0


def face_photographs(rng, distance_mm):
    """A textured disc on black (a face on a dark background) and its model-made target at
    one depth: the visible photograph and the near-infrared one of a model-made pair."""
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    disc = (((x - 21.5) / 17.0) ** 2 + ((y - 22.0) / 19.0) ** 2 < 1.0).astype(np.float64)
    fine = gaussian_filter(rng.standard_normal((SIZE, SIZE)), 0.7)
    coarse = gaussian_filter(rng.standard_normal((SIZE, SIZE)), 3.0)
    source = disc * np.clip(0.5 + 0.2 * fine / fine.std() + 0.1 * coarse / coarse.std(), 0.05, None)
    truth = invsss.SSSParams(TRUTH_LEVEL, 0.0, 1.0, [0.35, 0.65], PROFILE["variances"])
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(source, np.full((SIZE, SIZE), distance_mm), disc, truth))
    target = 0.9 * clean + 0.01 + 0.002 * rng.standard_normal(clean.shape)
    return source, target, disc
