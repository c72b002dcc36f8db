"""The published profile models of the spot measurement, against independent numbers."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from invsss.forward.profiles import burley, jensen_dipole, total_diffuse_reflectance
from invsss.measurement.profile_models import (
    PROFILE_MODELS,
    better_dipole,
    burley_albedo,
    burley_alpha,
    burley_medium,
    burley_parameters,
    burley_scaling,
    burley_searchlight,
    fresnel_moments,
    photon_beam,
    point_source_exitance,
)

R = np.linspace(1.5, 6.0, 10)


def test_burley_albedo_is_the_root_of_the_published_fit():
    # Cardano's root against a bracketing solver of the same equation.
    with jax.enable_x64(True):
        for alpha in (0.05, 0.4, 0.8, 0.965, 0.995):
            expected = brentq(lambda A: float(burley_alpha(A)) - alpha, 0.0, 2.0, xtol=1e-14)
            assert abs(float(burley_albedo(alpha)) - expected) < 1e-9


def test_burley_parameters_and_medium_are_inverse():
    with jax.enable_x64(True):
        for illumination in ("searchlight", "diffuse"):
            A, d = burley_parameters(jnp.array([0.7748, 0.88]), jnp.array([0.02808, 0.17]), illumination)
            s, a = burley_medium(A, d, illumination)
            np.testing.assert_allclose(s, [0.7748, 0.88], rtol=1e-10)
            np.testing.assert_allclose(a, [0.02808, 0.17], rtol=1e-10)
            # d = l / s(A), l the mean free path
            np.testing.assert_allclose(d * burley_scaling(A, illumination) * (s + a), 1.0, rtol=1e-12)


def test_burley_searchlight_is_the_normalized_diffusion_of_its_parameters():
    with jax.enable_x64(True):
        A, d = burley_parameters(0.7748, 0.02808)
        np.testing.assert_allclose(burley_searchlight(R, 0.7748, 0.02808), burley(R, d, A), rtol=1e-12)
        total = total_diffuse_reflectance(functools.partial(burley_searchlight, sigma_s_prime=0.7748,
                                                            sigma_a=0.02808))
        np.testing.assert_allclose(total, A, rtol=1e-3)


def test_fresnel_moments_match_egan_and_hilgeman():
    # 2 C1 is the internal diffuse Fresnel reflectance; Egan & Hilgeman's fit of it
    # (the one Jensen's dipole uses) agrees within its own accuracy.
    for eta in (1.2, 1.3, 1.4):
        c1, _ = fresnel_moments(eta)
        f_dr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
        assert abs(2.0 * float(c1) - f_dr) < 0.01
    c1, c2 = fresnel_moments(1.3)
    assert 0.0 < float(c2) < float(c1)


def test_better_dipole_far_from_a_weak_absorber_is_the_classical_dipole():
    # eta = 1 and sigma_a -> 0: Grosjean's D is the classical 1 / (3 sigma_t'), so the
    # image sources sit where Jensen's do, and far away the fluence at the surface is
    # 2 E (the extrapolated boundary), so phi / 4 + E / 2 is Jensen's E.
    with jax.enable_x64(True):
        r = np.array([6.0, 8.0, 10.0])
        ratio = np.asarray(better_dipole(r, 1.0, 1e-4, 1.0)) / np.asarray(jensen_dipole(r, 1.0, 1e-4, 1.0))
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)


def test_photon_beam_quadrature_against_a_dense_depth_integral():
    # Habel et al.'s integral along the beam, sigma_s' e^{-sigma_t' t} kappa(t) times the
    # point source's exitance, by the trapezoid rule on a fine depth grid.
    s, a, eta = 0.7748, 0.02808, 1.3
    t = np.linspace(0.0, 60.0, 60001)[:, None]
    with jax.enable_x64(True):
        kernel = np.asarray(point_source_exitance(R[None, :], t, s, a, eta))
        expected = np.trapezoid(s * np.exp(-(s + a) * t) * (1 - np.exp(-2 * (s + a) * (np.hypot(R, t) + t)))
                                * kernel, t[:, 0], axis=0)
        np.testing.assert_allclose(photon_beam(R, s, a, eta), expected, rtol=1e-4)
        single = np.asarray(better_dipole(R, s, a, eta))
    # The beam differs from one source at 1 / sigma_t' by more than the quadrature's error.
    assert np.max(np.abs(expected / single - 1)) > 0.05


@pytest.mark.parametrize("name", sorted(PROFILE_MODELS))
def test_model_derivatives_match_finite_differences(name):
    model = PROFILE_MODELS[name]
    with jax.enable_x64(True):
        def log_r(p):
            return jnp.log(model(jnp.asarray(R), jnp.exp(p[0]), jnp.exp(p[1]), 1.3))

        p = jnp.log(jnp.array([0.7748, 0.02808]))
        exact = np.asarray(jax.jacfwd(log_r)(p))
        h = 1e-6
        numeric = np.stack([(np.asarray(log_r(p + h * e)) - np.asarray(log_r(p - h * e))) / (2 * h)
                            for e in np.eye(2)], axis=1)
    np.testing.assert_allclose(exact, numeric, rtol=1e-5, atol=1e-8)
