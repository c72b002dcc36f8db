"""The fit's blur width in pixels (issue 47, "say what the pixels can measure").

``invsss.estimator.blur_width`` reduces a fit to the blur's RMS width per axis at the
skin's median depth: the models' second moments are checked against the blur each
model renders, the width's standard error against the fit's own, the resolution rule
(half the pixels, half the width in pixels) on a pair whose blur spans pixels. (That
a real photograph's channel pair, whose blur is under a pixel, says so at both
resolutions is tested from the command line, tests/cli/test_blur_width.py.)
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

import invsss
from invsss.estimator.blur_width import blur_width_px, second_moment
from tests.forward._estimator_scenes import textured_pair


@pytest.mark.parametrize("model, weights, variances", [
    ("sog", [0.3, 0.7], [1.0, 4.0]),
    ("thesis", [1.0, 1.0], [1.0, 2.25]),
    ("separable", [0.5, 0.5], [1.0, 2.25]),
    ("burley", [1.0], [0.25]),
])
def test_second_moment_is_what_the_model_renders(model, weights, variances):
    # An impulse on flat depth: the rendered image's per-axis variance (px^2) is the
    # profile's second moment times the stretch squared (4 px per mm, so that the
    # bilinear reads between pixels add little).
    size, level, depth = 101, 2000.0, 500.0
    image = np.zeros((size, size, 1))
    image[size // 2, size // 2] = 1.0
    with jax.enable_x64(True):
        params = invsss.SSSParams(level, 0.0, 1.0, weights, variances)
        out = np.asarray(invsss.render(image, np.full((size, size), depth), np.ones((size, size)), params, model))[..., 0]
    x = np.arange(size) - size // 2
    measured = float((out.sum(axis=0) * x**2).sum() / out.sum())
    expected = float(second_moment(model, np.asarray(weights), np.asarray(variances), np)[0]) * (level / depth) ** 2
    # The 7-tap passes and Burley's 32 samples approximate their profiles; a wrong
    # second moment (mixture versus sum, 7 d^2 versus 2 d^2) is off by far more.
    assert measured == pytest.approx(expected, rel=0.1)


def test_width_follows_the_stretch():
    values = {"sss_level": 600.0, "correction": 100.0, "maxdd": 0.5, "weights": np.array([1.0]),
              "variances": np.array([4.0])}
    flat = blur_width_px("sog", values, 600.0, 0.0, np)
    steep = blur_width_px("sog", values, 600.0, 2.0, np)  # slope clipped at maxdd
    np.testing.assert_allclose(flat, [2.0])
    np.testing.assert_allclose(steep, [600.0 * 2.0 / (600.0 + 100.0 * 0.5)])


def _half(a):
    return 0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])


@pytest.mark.slow
def test_resolution_rule_holds_within_the_standard_errors():
    # 6.4 px at full resolution (L 800, 16 mm^2, 500 mm): at half resolution 3.2 px. (At
    # 3.2 and 1.6 px the half-resolution fit reads 3 % wide, 9 standard errors: the passes'
    # bilinear reads and the texture's aliasing at 1.6 px; docs/capture.md.)
    source, target, depth, mask = textured_pair(96, 800.0, 16.0)
    single = {"weights": [1.0], "variances": [16.0]}
    fix = {"correction": 0.0, "maxdd": 1.0}
    full = invsss.fit_pair(source, target, depth, mask, profile=single, fix=fix, n_starts=1)
    half = invsss.fit_pair(_half(source), _half(target), _half(depth), _half(mask), profile=single, fix=fix,
                           n_starts=1)
    (w_full,), (e_full,) = full.blur["sigma_px"], full.blur["stderr_px"]
    (w_half,), (e_half,) = half.blur["sigma_px"], half.blur["stderr_px"]
    assert w_full == pytest.approx(6.4, rel=0.03) and full.blur["resolved"] and half.blur["resolved"]
    assert abs(w_full - 2.0 * w_half) <= 2.0 * np.hypot(e_full, 2.0 * e_half)
    # With only sss_level free, the width's relative error is sss_level's.
    assert e_full / w_full == pytest.approx(full.stderr["sss_level"] / float(full.values["sss_level"]), rel=1e-6)
