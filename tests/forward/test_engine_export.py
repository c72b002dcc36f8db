"""Parameters in another depth unit (issue 46): converted parameters render the same blur
on the depth in that unit, and a depth whose numbers look like cm gets a notice."""

from __future__ import annotations

import warnings

import jax
import numpy as np
import pytest

import invsss
from invsss.forward.params import check_plausible, convert_params
from invsss.validation import InputNotice

D = np.array([1.1, 0.55, 0.3])  # mm


@pytest.mark.parametrize("model, values", [
    ("sog", (600.0, 800.0, 0.5, [0.3, 0.7], [0.5, 4.0])),
    ("burley", (800.0, 0.0, 1.0, [1.0, 1.0, 1.0], D**2)),
])
def test_converted_parameters_render_the_same_blur(model, values):
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:24, 0:28].astype(np.float64)
    depth_mm = 480.0 + 1.5 * xx + 6.0 * np.sin(0.5 * yy)
    image = rng.uniform(0.1, 1.0, (24, 28, 3))
    mask = np.ones((24, 28))
    with jax.enable_x64(True):
        params = invsss.SSSParams(*values)  # float64, so that only the conversion differs
        in_mm = np.asarray(invsss.render(image, depth_mm, mask, params, model))
        in_cm = np.asarray(invsss.render(image, depth_mm / 10.0, mask, convert_params(params, "mm", "cm"), model))
        unconverted = np.asarray(invsss.render(image, depth_mm / 10.0, mask, params, model))
    np.testing.assert_allclose(in_cm, in_mm, rtol=0, atol=1e-10)
    assert np.abs(unconverted - in_mm).max() > 1e-2  # the test can tell the units apart


def test_depth_that_looks_like_cm_gets_a_notice():
    params = invsss.SSSParams(600.0, 0.0, 1.0, [1.0], [2.0])
    with pytest.warns(InputNotice, match="if the depth is in cm"):
        check_plausible(params, np.full((16, 16), 55.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_plausible(params, np.full((16, 16), 550.0)) == []
