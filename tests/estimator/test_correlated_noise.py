"""Standard errors stay honest when the noise is correlated between neighbouring pixels.

JPEG's blocks, demosaicking and sharpening correlate a photograph's noise over a
few pixels; a covariance that takes the noise as white then reports errors several
times too small. The covariance allows correlation within blocks of
``BLOCK_PX`` pixels (a cluster-robust sandwich). Checked here on one draw: the
reported error with and without the blocks (the scatter over noise draws against
the reported error, on a face, is measured by ``experiments/stderr_calibration.py``).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.estimator import uncertainty
from invsss.estimator.uncertainty import block_index

SHAPE = (48, 56)
TRUTH = invsss.SSSParams(500.0, 0.0, 1.0, [0.4, 0.6], [1.0, 4.0])
PROFILE = {"weights": [0.5, 0.5], "variances": [1.0, 4.0]}


def test_block_index_numbers_blocks_per_image_and_repeats_channels():
    index = block_index([(3, 5, 2), (2, 2, 1)], 2)
    # First image: 2 x 3 blocks, each pixel's two channels share its block.
    first = index[:30].reshape(3, 5, 2)
    assert np.array_equal(first[..., 0], first[..., 1])
    assert np.array_equal(first[..., 0], [[0, 0, 1, 1, 2], [0, 0, 1, 1, 2], [3, 3, 4, 4, 5]])
    # The second image's blocks are numbered after the first's.
    assert np.array_equal(index[30:], [6, 6, 6, 6])


def _error(noise_smooth: float) -> float:
    """The reported standard error of sss_level on a card whose noise is white
    (``noise_smooth`` 0) or smoothed by a Gaussian of that many pixels."""
    rng = np.random.default_rng(5)
    source = ndimage.gaussian_filter(rng.uniform(0.2, 1.0, SHAPE), 1.0)
    depth, mask = np.full(SHAPE, 500.0), np.ones(SHAPE)
    clean = np.asarray(invsss.render(source, depth, mask, TRUTH), np.float64)
    noise = rng.standard_normal(SHAPE)
    if noise_smooth:
        noise = ndimage.gaussian_filter(noise, noise_smooth)
    noise *= 0.01 / noise.std()
    fit = invsss.fit_pair(source, clean + noise, depth, mask, profile=PROFILE, n_starts=1,
                          fix={"correction": 0.0, "maxdd": 1.0})
    return float(fit.stderr["sss_level"])


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_correlated_noise_widens_the_errors_and_white_noise_does_not(monkeypatch):
    blocks = {"white": _error(0.0), "correlated": _error(1.0)}
    # One pixel per block: the noise taken as white (heteroscedastic at most).
    monkeypatch.setattr(uncertainty, "BLOCK_PX", 1)
    pixels = {"white": _error(0.0), "correlated": _error(1.0)}
    # White noise: the blocks change the error by no more than their own scatter.
    assert blocks["white"] == pytest.approx(pixels["white"], rel=0.15)
    # Noise smoothed over a pixel has about 4 pi = 12.6 times the variance of a
    # white one's mean over a block; what it does to sss_level, which lives at
    # the finest scales, is less, but it must show.
    assert blocks["correlated"] > 1.3 * pixels["correlated"]
