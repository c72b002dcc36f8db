"""The ``core-gaussian`` profile (issue 47): a blur that keeps part of the image sharp, as
the extra blur between a visible and a 940 nm image of skin does, is recovered with its
core's weight; one Gaussian cannot describe it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import ndimage

import invsss

DISTANCE, FOCAL = 500.0, 1000.0
CORE, SIGMA_PX = 0.45, 3.0
#: One depth for the frame, so the slope correction has nothing to act on (the photo route's hold).
HELD = {"correction": 0.0, "maxdd": 1.0}


def _pair(seed=0, size=72):
    """A textured source and its target blurred by the model with a core of weight CORE
    and a Gaussian of SIGMA_PX (the core a tenth of its width), times a gain of 2."""
    rng = np.random.default_rng(seed)
    source = 0.5 + 0.25 * ndimage.gaussian_filter(rng.normal(size=(size, size)), 1.5, mode="reflect") / 0.19
    level = SIGMA_PX * DISTANCE  # sigma_px = sqrt(v) sss_level / depth, with v = 1
    params = invsss.SSSParams(level, 0.0, 1.0, [CORE, 1.0 - CORE], [0.01, 1.0])
    depth, mask = np.full((size, size), DISTANCE), np.ones((size, size))
    target = 2.0 * np.asarray(invsss.render(source[..., None], depth, mask, params))
    return invsss.ImagePair(source[..., None], target, depth, mask)


def _fit(pair, profile):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return invsss.fit_pairs([pair], profile=profile, fix=HELD, n_starts=2, focal_px=FOCAL)


@pytest.mark.slow
def test_core_and_gaussian_recovers_the_core_that_one_gaussian_misses():
    pair = _pair()
    core = _fit(pair, "core-gaussian")
    params = core.params
    weights = np.asarray(params.weights).ravel()
    weights = weights / weights.sum()
    sigmas = np.sqrt(np.asarray(params.variances)) * float(params.sss_level) / DISTANCE
    assert weights[0] == pytest.approx(CORE, abs=0.01)
    assert sigmas[1] == pytest.approx(SIGMA_PX, rel=0.01)
    assert not core.undetermined
    single = _fit(pair, "single")
    # One Gaussian trades the sharp part against the wide one: it reads a narrow blur and
    # leaves what it cannot describe in the residual.
    assert single.blur["sigma_px"][0] < 0.75 * SIGMA_PX
    assert core.psnr > single.psnr + 10.0


def test_core_gaussian_is_a_named_profile():
    profile = invsss.load_profile("core-gaussian")
    assert profile.num_gaussians == 2 and "core-gaussian" in invsss.PROFILE_NAMES
    np.testing.assert_allclose(np.asarray(profile.variances), [0.01, 1.0])
