"""Diffusion profiles: dipole, Burley, sums of Gaussians, tables and the profile file."""

import functools
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import invsss
from invsss import (
    DEON_SKIN_RGB,
    JENSEN_SKIN1,
    THESIS_NIR_940,
    InvalidInputError,
    SumOfGaussians,
    burley,
    jensen_dipole,
    jensen_dipole_total,
    load_profile,
    total_diffuse_reflectance,
)

SKIN1 = (np.array(JENSEN_SKIN1["sigma_s_prime"]), np.array(JENSEN_SKIN1["sigma_a"]), JENSEN_SKIN1["eta"])


def _quad_plane_integral(profile_at):
    # 2 pi int_0^inf R(r) r dr by adaptive quadrature, split where skin profiles bend.
    integrand = lambda r: 2.0 * np.pi * r * profile_at(r)  # noqa: E731
    pieces = [(0.0, 1.0), (1.0, 10.0), (10.0, np.inf)]
    return sum(integrate.quad(integrand, a, b, epsabs=1e-13, epsrel=1e-11, limit=200)[0] for a, b in pieces)


# ------------------------------------------------------------------ dipole


@pytest.mark.slow
@pytest.mark.parametrize("channel", [0, 1, 2])
def test_dipole_integral_matches_closed_form(channel):
    s, a, eta = SKIN1[0][channel], SKIN1[1][channel], SKIN1[2]
    with jax.enable_x64(True):
        profile_at = lambda r: float(jensen_dipole(r, s, a, eta))  # noqa: E731
        numeric = _quad_plane_integral(profile_at)
        closed = float(jensen_dipole_total(s, a, eta))
        dipole = functools.partial(jensen_dipole, sigma_s_prime=s, sigma_a=a)
        trapezoid = float(total_diffuse_reflectance(dipole))
    # quad is good to ~1e-11 here; the closed form is exact: agreement to 1e-9 leaves
    # no room for a wrong sign, factor or exponent anywhere in either formula.
    assert numeric == pytest.approx(closed, rel=1e-9)
    # The log-r trapezoid on 4097 points converges far below 1e-8; r_max = 100 mm
    # cuts a red tail of about exp(-0.27 * 100).
    assert trapezoid == pytest.approx(closed, rel=1e-8)


@pytest.mark.slow
def test_dipole_matches_thesis_form_and_vectorises_over_channels():
    # Thesis eq. 3.4 writes the same function as alpha'/(4 pi) [z (s_tr + 1/d) e^{-s_tr d} / d^2 ...];
    # evaluate that form independently in NumPy.
    s, a, eta = SKIN1
    r = np.array([0.0, 0.1, 0.5, 1.0, 2.5, 7.0])
    sigma_t = s + a
    alpha = s / sigma_t
    sigma_tr = np.sqrt(3 * a * sigma_t)
    f_dr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    big_a = (1 + f_dr) / (1 - f_dr)
    z_r = 1 / sigma_t
    z_v = z_r * (1 + 4 * big_a / 3)
    d_r = np.sqrt(r[:, None] ** 2 + z_r**2)
    d_v = np.sqrt(r[:, None] ** 2 + z_v**2)
    expected = alpha / (4 * np.pi) * (
        z_r * (sigma_tr + 1 / d_r) * np.exp(-sigma_tr * d_r) / d_r**2
        + z_v * (sigma_tr + 1 / d_v) * np.exp(-sigma_tr * d_v) / d_v**2
    )
    with jax.enable_x64(True):
        got = np.asarray(jensen_dipole(r, s, a, eta))
        per_channel = np.stack([np.asarray(jensen_dipole(r, s[c], a[c], eta)) for c in range(3)], axis=1)
    assert got.shape == (6, 3)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    np.testing.assert_allclose(per_channel, got, rtol=1e-14)


@pytest.mark.slow
def test_dipole_gradients_match_finite_differences():
    with jax.enable_x64(True):
        r = jnp.array([0.3, 1.7])

        def total(params):
            s, a, eta = params
            return jnp.sum(jensen_dipole(r, s, a, eta) * jnp.array([1.0, 2.0]))

        x = jnp.array([0.74, 0.032, 1.3])
        grad = np.asarray(jax.grad(lambda p: total(p))(x))
        eps = 1e-6
        fd = np.array(
            [
                (float(total(x.at[i].add(eps))) - float(total(x.at[i].add(-eps)))) / (2 * eps)
                for i in range(3)
            ]
        )
    np.testing.assert_allclose(grad, fd, rtol=1e-6)


# ------------------------------------------------------------------ Burley


@pytest.mark.parametrize("d", [0.3, 1.0, 2.5])
def test_burley_integrates_to_A(d):
    albedo = 0.7
    with jax.enable_x64(True):
        numeric = _quad_plane_integral(lambda r: float(burley(r, d, albedo)))
        trapezoid = float(total_diffuse_reflectance(functools.partial(burley, d=d, A=albedo), r_max=200.0))
    # The clamp at r < 1e-6 d changes ~1e-6 of the energy (r R is finite there).
    assert numeric == pytest.approx(albedo, rel=1e-5)
    assert trapezoid == pytest.approx(albedo, rel=1e-5)


def test_burley_is_finite_and_differentiable_at_zero():
    with jax.enable_x64(True):
        value = burley(jnp.array(0.0), 1.0, 0.5)
        grads = jax.grad(lambda d, a: burley(jnp.array(0.0), d, a), argnums=(0, 1))(1.0, 0.5)
        away = float(burley(jnp.array(0.8), 1.3, 0.5))
    assert np.isfinite(float(value)) and float(value) > 1e4
    assert all(np.isfinite(float(g)) for g in grads)
    expected = 0.5 * (np.exp(-0.8 / 1.3) + np.exp(-0.8 / 3.9)) / (8 * np.pi * 1.3 * 0.8)
    assert away == pytest.approx(expected, rel=1e-12)


@pytest.mark.slow
def test_burley_gradient_matches_finite_differences():
    with jax.enable_x64(True):
        r = jnp.linspace(0.1, 3.0, 7)
        f = lambda d: jnp.sum(burley(r, d, 0.8))  # noqa: E731
        grad = float(jax.grad(f)(0.9))
        fd = (float(f(0.9 + 1e-6)) - float(f(0.9 - 1e-6))) / 2e-6
    assert grad == pytest.approx(fd, rel=1e-7)


# ------------------------------------------------------------------ sums of Gaussians


@pytest.mark.parametrize("name", ["thesis-nir", "deon-skin"])
def test_sum_of_gaussians_integrates_to_sum_of_weights(name):
    with jax.enable_x64(True):
        profile = load_profile(name)
        trapezoid = np.asarray(total_diffuse_reflectance(profile))
        closed = np.asarray(profile.total_reflectance())
        weights = np.asarray(profile.weights)
        first = lambda r: float(np.atleast_1d(np.asarray(profile(r)))[0])  # noqa: E731
        numeric = _quad_plane_integral(first)
    np.testing.assert_allclose(closed, weights.sum(axis=0), rtol=1e-15)
    np.testing.assert_allclose(trapezoid, closed, rtol=1e-9)
    assert numeric == pytest.approx(float(np.atleast_1d(closed)[0]), rel=1e-9)


def test_published_tables_are_consistent_and_immutable():
    # d'Eon & Luebke normalised their RGB fit to a white total: each channel sums to 1.
    np.testing.assert_allclose(np.sum(DEON_SKIN_RGB["weights"], axis=0), 1.0, atol=1e-12)
    # Five Gaussians in the thesis's Table 5.1, one weight per variance.
    assert len(THESIS_NIR_940["variances"]) == len(THESIS_NIR_940["weights"]) == 5
    for table in (THESIS_NIR_940, DEON_SKIN_RGB, JENSEN_SKIN1):
        assert table["source"]
        with pytest.raises(TypeError):
            table["variances"] = (1.0,)


@pytest.mark.slow
def test_sum_of_gaussians_module_matches_function_and_transforms():
    with jax.enable_x64(True):
        profile = load_profile("deon-skin")
        r = jnp.linspace(0.0, 4.0, 9)
        direct = invsss.sum_of_gaussians(r, profile.weights, profile.variances)
        jitted = eqx.filter_jit(lambda p, x: p(x))(profile, r)
        # vmap over a batch of profiles (variances scaled), and grad w.r.t. variances.
        scales = jnp.array([0.5, 1.0, 2.0])
        batch = jax.vmap(lambda s: SumOfGaussians(profile.weights, profile.variances * s)(r))(scales)
        grad = jax.grad(lambda v: jnp.sum(SumOfGaussians(profile.weights, v)(r)))(profile.variances)
        eps = 1e-7
        i = 3

        def bump(e):
            bumped = SumOfGaussians(profile.weights, profile.variances.at[i].add(e))
            return float(jnp.sum(bumped(r)))

        fd = (bump(eps) - bump(-eps)) / (2 * eps)
        reversed_profile = SumOfGaussians(profile.weights[::-1], profile.variances[::-1])
        sorted_profile = reversed_profile.sorted()
        sorted_values = sorted_profile(r)
    np.testing.assert_allclose(jitted, direct, rtol=1e-14)
    np.testing.assert_allclose(batch[1], direct, rtol=1e-14)
    assert batch.shape == (3, 9, 3)
    assert float(grad[i]) == pytest.approx(fd, rel=1e-6)
    np.testing.assert_array_equal(sorted_profile.variances, profile.variances)
    np.testing.assert_allclose(sorted_values, direct, rtol=1e-14)


# ------------------------------------------------------------------ profile files


def test_load_profile_names_and_json_round_trip(tmp_path):
    thesis = load_profile("thesis-nir")
    deon = load_profile("deon-skin")
    assert thesis.weights.shape == (5,) and thesis.num_channels is None
    assert deon.weights.shape == (6, 3) and deon.num_channels == 3
    path = tmp_path / "deon.json"
    path.write_text(json.dumps(deon.to_dict()))
    again = load_profile(path)
    assert again.source == deon.source
    np.testing.assert_array_equal(again.weights, deon.weights)
    np.testing.assert_array_equal(again.variances, deon.variances)
    assert load_profile(str(path)).num_gaussians == 6


@pytest.mark.parametrize(
    "content, fragment",
    [
        ("{not json", "not valid JSON"),
        ("[1, 2]", "expected a mapping"),
        ('{"weights": [1.0]}', "missing key(s) variances"),
        ('{"weights": [1.0], "variances": [0.0]}', "variances must be > 0"),
        ('{"weights": [-1.0, 2.0], "variances": [1.0, 2.0]}', "weights must be >= 0"),
        ('{"weights": [1.0, 2.0], "variances": [1.0]}', "weights must have shape (1,)"),
        ('{"weights": [1.0], "variances": [1.0], "colour": 1}', "unknown key(s) colour"),
        ('{"weights": ["a"], "variances": [1.0]}', 'weights[0]: expected a number, got "a"'),
        ('{"weights": [true], "variances": [1.0]}', "weights[0]: expected a number, got true"),
    ],
)
def test_bad_profile_files_raise_one_line_errors(tmp_path, content, fragment):
    path = tmp_path / "profile.json"
    path.write_text(content)
    with pytest.raises(InvalidInputError) as info:
        load_profile(path)
    message = str(info.value)
    assert fragment in message and str(path) in message and "\n" not in message


def test_unknown_name_and_missing_file_raise(tmp_path):
    with pytest.raises(InvalidInputError, match="unknown name 'skin'.*thesis-nir, deon-skin, jensen-skin1"):
        load_profile("skin")
    with pytest.raises(InvalidInputError, match="profile file not found"):
        load_profile(tmp_path / "missing.json")
    with pytest.raises(InvalidInputError, match="expected a name or a JSON file path"):
        load_profile(3)


@pytest.mark.slow
def test_jensen_skin1_fit_table_follows_the_dipole():
    s, a, eta = SKIN1
    with jax.enable_x64(True):
        table = load_profile("jensen-skin1")
        r = jnp.linspace(0.0, 8.0, 801)
        truth = np.asarray(jensen_dipole(r, s, a, eta))
        fitted = np.asarray(table(r))
    assert table.weights.shape == (5, 3)
    # The table was fitted on [0, 8] mm (experiments/fit_profiles.py): within 1.74 %
    # where the dipole is above 1 % of its peak; 2.5 % catches a mistyped digit.
    visible = truth >= 0.01 * truth.max(axis=0)
    assert np.max(np.abs(fitted / truth - 1.0)[visible]) < 0.025
