"""The pigment field (issue 47): a smooth gain per target channel that nests and cannot take the blur's place."""

from __future__ import annotations

import warnings

import jax
import numpy as np
import pytest

import invsss
from invsss.estimator.pigment import pigment_at, pigment_field, term_names
from invsss.validation import InvalidInputError
from tests.forward._estimator_scenes import textured_pair


#: A face-wide colour difference of up to +-0.25 (red cheeks, a bluish forehead).
A_TRUE = np.array([[0.15, -0.1, 0.05], [0.0, 0.1, -0.1], [-0.1, 0.0, 0.05], [0.05, 0.05, 0.0], [0.0, -0.1, 0.1]])
SINGLE = {"weights": [1.0], "variances": [4.0]}
FIX = {"correction": 0.0, "maxdd": 1.0}


def test_field_is_the_identity_at_zero_and_matches_its_pointwise_form():
    zero = np.asarray(pigment_field(np.zeros((5, 3)), (7, 9)))
    np.testing.assert_array_equal(zero, np.ones((7, 9, 3)))
    with jax.enable_x64(True):
        field = np.asarray(pigment_field(A_TRUE, (7, 9)))
    rows, cols = np.mgrid[0:7, 0:9]
    at = pigment_at(A_TRUE, np.stack([rows.ravel(), cols.ravel()], axis=1), (7, 9))
    np.testing.assert_allclose(at.reshape(7, 9, 3), field, rtol=1e-12)
    # u runs along the columns, v along the rows, each from -1 to 1.
    assert field[3, 8, 0] == pytest.approx(1.0 + 0.15 - 0.1 * 1.0) and field[0, 4, 1] == pytest.approx(1.0 - 0.1 - 0.1)
    assert term_names(1) == ["u", "v"]


def test_degree_is_checked_in_one_line():
    with pytest.raises(InvalidInputError, match="pigment: expected a degree among 0, 1, 2"):
        invsss.FitOptions(pigment=3)


def _colour_pair(field):
    source, _, depth, mask = textured_pair(64, 800.0, 4.0)
    rgb = np.repeat(source, 3, axis=-1) * np.array([1.0, 0.8, 0.7])
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(rgb, depth, mask, invsss.SSSParams(800.0, 0.0, 1.0, [1.0], [4.0])))
        shade = np.asarray(pigment_field(field, (64, 64)))
    target = clean * shade + 0.003 * np.random.default_rng(1).standard_normal(clean.shape)
    return rgb, target, depth, mask


def _fit(pair, pigment):
    # Plain least squares: a robust fit's loss carries its own weights, so two fits'
    # losses compare only without them.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return invsss.fit_pair(*pair, profile=SINGLE, fix=FIX, n_starts=1, pigment=pigment, robust="none")


@pytest.mark.slow
def test_a_colour_field_biases_the_blur_until_the_field_takes_it():
    pair = _colour_pair(A_TRUE)
    plain, fitted = _fit(pair, 0), _fit(pair, 2)
    level = float(fitted.values["sss_level"])
    assert abs(level - 800.0) < 3.0 * fitted.stderr["sss_level"] < 0.001 * 800.0
    # Without the field the fit leans on the blur (803 +- 2 measured) and loses 20 dB.
    assert fitted.psnr > plain.psnr + 15.0 and fitted.pigment["psnr_without"] < fitted.psnr - 15.0
    np.testing.assert_allclose(fitted.pigment["coefficients"], A_TRUE, atol=0.002)


@pytest.mark.slow
def test_the_field_does_not_take_the_blurs_place():
    # No pigment in the target: the field stays at its identity, within its standard
    # errors, and the blur is the plain fit's.
    pair = _colour_pair(np.zeros_like(A_TRUE))
    plain, fitted = _fit(pair, 0), _fit(pair, 2)
    a, err = np.asarray(fitted.pigment["coefficients"]), np.asarray(fitted.pigment["stderr"], np.float64)
    assert np.all(np.abs(a) < 4.0 * err)
    both = np.hypot(plain.stderr["sss_level"], fitted.stderr["sss_level"])
    assert abs(float(fitted.values["sss_level"]) - float(plain.values["sss_level"])) < 2.0 * both
    assert fitted.loss <= plain.loss * (1.0 + 1e-6)
