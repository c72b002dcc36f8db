"""The fitted vignetting field: its definition, its derivative, and what it buys a fit.

A model-made face is photographed through a lens whose corners get 20 % less
light. A fit that knows about vignetting must land where the fit of the same
photograph without vignetting lands (same noise draw), and say how strong the
fall-off was; a fit that does not know about it is measurably pulled away.

The fit with the field against the unshaded fit, and the field in the report and in
params.json, are tested from the command line (tests/cli/test_vignetting.py).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss import InvalidInputError
from invsss.estimator import FitOptions, build_problem
from invsss.estimator.vignetting import radius_squared, vignetting_at, vignetting_field
from tests.forward._estimator_scenes import make_pair
from tests.forward._vignetted_face import OFFSET, PROFILE3, SIZE, TRUTH, photographs


@pytest.mark.slow
@jax.enable_x64(True)
def test_field_matches_its_definition():
    rho2 = np.asarray(radius_squared((4, 6), jnp.float64))
    y, x = np.mgrid[0:4, 0:6]
    expected = ((y - 1.5) ** 2 + (x - 2.5) ** 2) / (1.5**2 + 2.5**2)
    np.testing.assert_allclose(rho2, expected, rtol=1e-12)
    field = np.asarray(vignetting_field(jnp.array([-0.3, 0.1], jnp.float64), (4, 6)))
    np.testing.assert_allclose(field, 1.0 - 0.3 * expected + 0.1 * expected**2, rtol=1e-12)
    # Read at the pixel centres, the field at any points is the same field.
    points = np.stack([y.ravel(), x.ravel()], axis=1).astype(float)
    np.testing.assert_allclose(vignetting_at([-0.3, 0.1], points, (4, 6)), field.ravel(), rtol=1e-12)
    between = vignetting_at([-0.3, 0.1], np.array([[0.5, 1.0]]), (4, 6))[0]
    rho2_between = (1.0**2 + 1.5**2) / (1.5**2 + 2.5**2)
    assert between == pytest.approx(1.0 - 0.3 * rho2_between + 0.1 * rho2_between**2, rel=1e-12)


@pytest.mark.slow
def test_projected_residual_derivative_in_the_vignetting_block():
    source, depth, mask, _, photo = photographs()
    problem = build_problem([(source[:24, :24], photo[:24, :24], depth[:24, :24], mask[:24, :24])],
                            FitOptions(profile=PROFILE3, vignetting=True))
    assert problem.param.free[-1] == "vignetting"
    with jax.enable_x64(True):
        f = jax.jit(lambda u: problem.objective(u)[0])
        z = jnp.asarray(problem.z0).at[-2:].set(jnp.array([-0.15, 0.05]))
        jac = np.asarray(jax.jacfwd(f)(z))
        h = 1e-6
        for k in (z.size - 2, z.size - 1):
            e = jnp.zeros_like(z).at[k].set(h)
            fd = (np.asarray(f(z + e)) - np.asarray(f(z - e))) / (2 * h)
            assert np.linalg.norm(fd) > 0
            assert np.linalg.norm(jac[:, k] - fd) < 1e-6 * np.linalg.norm(fd)


@pytest.fixture(scope="module")
def fits():
    source, depth, mask, plain, shaded = photographs()
    kw = {"profile": PROFILE3, "n_starts": 2}
    return {
        "reference": invsss.fit_pair(source, plain, depth, mask, **kw),
        "shaded": invsss.fit_pair(source, shaded, depth, mask, **kw),
        "shaded, fitted": invsss.fit_pair(source, shaded, depth, mask, vignetting=True, **kw),
    }


@pytest.mark.slow
def test_ignoring_vignetting_biases_the_fit(fits):
    reference, ignored = fits["reference"], fits["shaded"]
    worst = max(abs(float(ignored.values[n]) - float(reference.values[n])) / reference.stderr[n]
                for n in ("sss_level", "correction", "maxdd"))
    assert worst > 10
    assert ignored.sigma > 2 * reference.sigma


def test_vignetting_option_is_checked():
    with pytest.raises(InvalidInputError, match=r"^vignetting: expected true or false, got 'yes'$"):
        FitOptions(vignetting="yes")


@pytest.mark.slow
def test_registration_does_not_take_the_fall_off_for_a_zoom():
    # A photograph moved by whole pixels (nothing interpolated), then shaded about
    # its own frame's centre: an aligned fit with vignetting must find the move and
    # no zoom. Registering against an unshaded prediction read the fall-off as a
    # scale of about 0.999, which moves correction by several per cent.
    source, depth, mask, _, _ = photographs()
    _, _, _, _, clean = make_pair("face", TRUTH, size=SIZE, contrast=3.0, seed=4, noise=0.0)
    moved = np.full_like(clean, OFFSET)
    moved[2:, :-1] = clean[:-2, 1:]  # content 2 rows down and 1 column left
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    c = (SIZE - 1) / 2.0
    rho2 = ((y - c) ** 2 + (x - c) ** 2) / (2 * c**2)
    noise = 0.01 * float(np.mean(clean[mask > 0])) * np.random.default_rng(5).standard_normal(clean.shape)
    photo = (moved - OFFSET) * (1.0 - 0.2 * rho2)[..., None] + OFFSET + noise
    fit = invsss.fit_pair(source, photo, depth, mask, profile=PROFILE3, n_starts=2, align="similarity",
                          vignetting=True)
    warp = fit.alignment[0]
    assert warp["shift_px"] == pytest.approx([2.0, -1.0], abs=0.02)
    assert abs(warp["scale"] - 1.0) < 2e-4 and abs(warp["rotation_deg"]) < 0.02
    assert fit.vignetting["corner_gain"] == pytest.approx(0.8, abs=0.02)
