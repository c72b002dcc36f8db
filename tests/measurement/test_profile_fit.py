"""Sum-of-Gaussians fitting: recovery of known profiles and fits of the published ones.

Every single-channel fit here uses 121 radii and 5 Gaussians, and every RGB fit the
same, so the fitter compiles twice for the whole file.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from invsss import (
    JENSEN_SKIN1,
    InvalidInputError,
    SumOfGaussians,
    burley,
    fit_sum_of_gaussians,
    jensen_dipole,
    load_profile,
)

N, K = 121, 5
TRUTH_W = np.array([0.10, 0.15, 0.20, 0.15, 0.10])
TRUTH_V = np.array([0.05, 0.2, 0.8, 3.2, 12.8])  # four times apart: well separated


def _truth():
    return SumOfGaussians(jnp.asarray(TRUTH_W), jnp.asarray(TRUTH_V))


@pytest.mark.slow
def test_recovers_known_sum_of_gaussians():
    with jax.enable_x64(True):
        r = jnp.linspace(0.0, 12.0, N)
        fit = fit_sum_of_gaussians(r, _truth()(r), num_gaussians=K)
        v, w = np.asarray(fit.profile.variances), np.asarray(fit.profile.weights)
    # Noise-free data in float64 with solver tolerances of 1e-8: the parameters come
    # back to ~1e-10 (measured); 1e-6 fails for any wrong start, local minimum or a
    # weight stuck at the non-negativity bound.
    np.testing.assert_allclose(v, TRUTH_V, rtol=1e-6)
    np.testing.assert_allclose(w, TRUTH_W, rtol=1e-6)
    assert bool(fit.converged)
    assert float(fit.rms) < 1e-9


@pytest.mark.slow
def test_fit_of_noisy_profile_behaves_like_least_squares():
    # White noise of deviation sigma on every sample, fitted unweighted: textbook
    # least squares with p = 2K = 10 parameters and N = 121 samples.
    rng = np.random.default_rng(7)
    with jax.enable_x64(True):
        r = jnp.linspace(0.0, 12.0, N)
        clean = np.asarray(_truth()(r))
        sigma = 1e-3 * clean.max()
        noisy = clean + sigma * rng.standard_normal(N)
        fit = fit_sum_of_gaussians(r, noisy, num_gaussians=K, weighting="none")
        fitted = np.asarray(fit.profile(r))
    residual = float(fit.rms) * np.linalg.norm(noisy)
    error = np.linalg.norm(fitted - clean)
    # ||residual||^2 / sigma^2 ~ chi2(N - p): its root is 10.5 +- 0.7 (one deviation);
    # measured 8.9 for this seed (8.9 to 11.1 over seeds 0-7). The bounds sit 3.5
    # deviations out: a solver stuck short of the minimum leaves more, a broken one
    # that fits the noise less.
    assert 8.0 < residual / sigma < 13.0
    assert bool(fit.converged)
    # ||fit - truth||^2 / sigma^2 ~ chi2(p): sqrt(10) = 3.2 typical, > 6.6 has
    # probability < 1e-5; measured 3.5.
    assert error / sigma < 6.6


@pytest.mark.slow
def test_refit_of_thesis_table_reproduces_its_curve():
    with jax.enable_x64(True):
        thesis = load_profile("thesis-nir")
        r = jnp.linspace(0.0, 12.0, N)
        fit = fit_sum_of_gaussians(r, thesis(r), num_gaussians=K)
        dense = jnp.linspace(0.0, 12.0, 1001)
        relative = np.abs(np.asarray(fit.profile(dense)) / np.asarray(thesis(dense)) - 1.0)
        total = float(jnp.sum(fit.profile.weights))
    # The table's Gaussians at 0.549 and 0.5574 mm^2 are nearly one, so its parameters
    # are not identifiable, but its curve is representable exactly: measured 3e-8.
    assert relative.max() < 1e-6
    assert total == pytest.approx(0.4232, rel=1e-6)


@pytest.mark.slow
def test_fits_jensen_dipole_skin1_per_channel():
    s, a = np.array(JENSEN_SKIN1["sigma_s_prime"]), np.array(JENSEN_SKIN1["sigma_a"])
    with jax.enable_x64(True):
        r = jnp.linspace(0.0, 8.0, N)
        fit = fit_sum_of_gaussians(r, jensen_dipole(r, s, a), num_gaussians=K)
        dense = jnp.linspace(0.0, 8.0, 801)
        truth = np.asarray(jensen_dipole(dense, s, a))
        relative = np.abs(np.asarray(fit.profile(dense)) / truth - 1.0)
    assert fit.profile.weights.shape == (K, 3)  # shared variances, RGB weights (d'Eon)
    assert np.all(np.diff(np.asarray(fit.profile.variances)) > 0)
    # Where the profile is within a factor 100 of its peak (red to 6 mm, blue to 2 mm)
    # five Gaussians stay within 1.8 % of the dipole (measured; d'Eon & Luebke report
    # fits of this quality). Four Gaussians give 5.5 %, so 2.5 % tells the difference.
    visible = truth >= 0.01 * truth.max(axis=0)
    assert relative[visible].max() < 0.025


@pytest.mark.slow
def test_fits_burley_normalized_diffusion():
    d, albedo = 1.0, 0.8
    with jax.enable_x64(True):
        r = jnp.linspace(0.0, 12.0 * d, N)  # r = 0 carries zero weight in the r-weighting
        fit = fit_sum_of_gaussians(r, burley(r, d, albedo), num_gaussians=K)
        dense = jnp.linspace(0.25 * d, 4.0 * d, 400)
        relative = np.abs(np.asarray(fit.profile(dense)) / np.asarray(burley(dense, d, albedo)) - 1.0)
        total = float(fit.profile.total_reflectance())
    # Gaussians cannot follow the 1/r peak nor the exp(-r / 3d) tail; on the bulk of the
    # energy the fit is within 4 % (measured 2.1 % weighted rms, 4.0 % pointwise).
    assert float(fit.rms) < 0.03
    assert relative.max() < 0.05
    # Its total is the sum of its weights; Burley's is A. The fit misses the tail past
    # 12 d (1.4 % of the energy) and a little of the peak: measured 3.5 % low.
    assert total == pytest.approx(albedo, rel=0.05)


@pytest.mark.slow
def test_shared_weights_across_channels():
    with jax.enable_x64(True):
        r = jnp.linspace(0.0, 12.0, N)
        one = np.asarray(_truth()(r))
        grey = np.stack([one, one, one], axis=1)
        fit = fit_sum_of_gaussians(r, grey, num_gaussians=K, weights_per_channel=False)
    assert fit.profile.weights.shape == (K,)
    np.testing.assert_allclose(np.asarray(fit.profile.variances), TRUTH_V, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(fit.profile.weights), TRUTH_W, rtol=1e-6)


def test_fit_result_round_trips_as_profile_file():
    with jax.enable_x64(True):
        r = jnp.linspace(0.0, 12.0, N)
        fit = fit_sum_of_gaussians(r, _truth()(r), num_gaussians=K, source="unit test")
        d = fit.to_dict()
        again = SumOfGaussians.from_dict(d)
    assert d["source"] == "unit test" and d["fit"]["weighting"] == "r" and d["fit"]["converged"]
    np.testing.assert_allclose(np.asarray(again.variances), np.asarray(fit.profile.variances), rtol=1e-15)


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        (dict(r=np.array([0.0, 2.0, 1.0])), "r: expected finite, non-negative, strictly increasing"),
        (dict(r=np.zeros((3, 2))), "r: expected a 1-D array"),
        (dict(profile=np.ones(4)), "profile: expected shape (5,) or (5, C)"),
        (dict(profile=np.array([1.0, np.nan, 1.0, 1.0, 1.0])), "profile: contains NaN"),
        (dict(profile=-np.ones(5)), "profile: has no positive value"),
        (dict(num_gaussians=0), "num_gaussians: expected an integer >= 1"),
        (dict(num_gaussians=2.5), "num_gaussians: expected an integer >= 1"),
        (dict(num_gaussians=11), "num_gaussians: at most 10"),
        (dict(weighting="log"), "weighting: expected one of r, relative, none"),
        (dict(weighting=-np.ones(5)), "weighting: expected finite non-negative sample weights"),
        (dict(variance_range=(2.0, 1.0)), "variance_range: expected (low, high)"),
        (dict(num_starts=0), "num_starts: expected an integer >= 1"),
    ],
)
def test_bad_inputs_raise_one_line_errors(kwargs, fragment):
    args = dict(r=np.linspace(0.0, 4.0, 5), profile=np.exp(-np.linspace(0.0, 4.0, 5)), num_gaussians=2)
    args.update(kwargs)
    with pytest.raises(InvalidInputError) as info:
        fit_sum_of_gaussians(args.pop("r"), args.pop("profile"), **args)
    assert fragment in str(info.value) and "\n" not in str(info.value)
