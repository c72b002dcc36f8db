"""A model-made face photographed through a lens whose corners get 20 % less light,
for the vignetting tests."""

from __future__ import annotations

import numpy as np

import invsss
from tests.forward._estimator_scenes import make_pair

PROFILE3 = {"weights": [0.3, 0.45, 0.25], "variances": [0.25, 1.2, 5.0]}
TRUTH = invsss.SSSParams(700.0, 300.0, 2.0, PROFILE3["weights"], PROFILE3["variances"])
SIZE = 80
OFFSET = 0.05  # make_pair's black level, which the lens does not shade


def photographs(seed=4):
    """Source, depth, mask, the photograph without vignetting and with it (one noise draw)."""
    source, _, depth, mask, clean = make_pair("face", TRUTH, size=SIZE, contrast=3.0, seed=seed, noise=0.0)
    noise = 0.01 * float(np.mean(clean[mask > 0])) * np.random.default_rng(seed).standard_normal(clean.shape)
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    c = (SIZE - 1) / 2.0
    rho2 = ((y - c) ** 2 + (x - c) ** 2) / (2 * c**2)  # written out, independent of the module
    shaded = (clean - OFFSET) * (1.0 - 0.2 * rho2)[..., None] + OFFSET
    return source, depth, mask, clean + noise, shaded + noise
