"""The host's NumPy paths agree with the traced JAX ones they stand in for.

``Parametrisation.natural``, ``depth_slopes`` and ``sum_of_gaussians`` take NumPy
arrays on the host (reading a result, sizing the start scan, drawing the report) so
that a fit compiles no eager JAX operations there; the two paths must give the same
numbers.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from invsss.estimator.parametrisation import SCALED_BLOCKS, Parametrisation
from invsss.forward.profiles import sum_of_gaussians
from invsss.forward.stretch import depth_slopes

BLOCKS = (("sss_level", ()), ("correction", ()), ("maxdd", ()), ("weights", (2,)), ("mix", (2, 3)),
          ("variances", (4,)), ("gain_ratio", (2,)), (SCALED_BLOCKS[0], (2,)))


def _param(rng) -> Parametrisation:
    reference = {name: np.abs(rng.normal(1.0, 0.3, shape)) + 0.1 for name, shape in BLOCKS
                 if name not in ("weights", "mix")}
    reference.update(weights=np.ones(3), mix=np.ones((2, 3)))
    return Parametrisation(BLOCKS, reference, {"tap_weights": np.arange(7.0)})


def test_natural_is_the_same_in_numpy_and_jax():
    rng = np.random.default_rng(4)
    param = _param(rng)
    z = rng.normal(0.0, 2.0, param.size)
    with jax.enable_x64(True):
        traced = eqx.filter_jit(lambda p, u: p.natural(u))(param, jnp.asarray(z))
    host = param.natural(z)
    assert set(host) == set(traced)
    for name, value in host.items():
        assert not isinstance(value, jax.Array), name
        np.testing.assert_allclose(value, np.asarray(traced[name]), rtol=1e-12, atol=1e-15, err_msg=name)
    # The simplex blocks are points of the simplex, and the map inverts.
    np.testing.assert_allclose(host["weights"].sum(), 1.0, rtol=1e-12)
    np.testing.assert_allclose(host["mix"].sum(axis=0), 1.0, rtol=1e-12)
    with jax.enable_x64(True):
        np.testing.assert_allclose(np.asarray(param.unknowns(host)), z, rtol=1e-8, atol=1e-9)


def test_the_simplex_stays_finite_for_large_unknowns():
    param = Parametrisation((("weights", (2,)),), {"weights": np.ones(3)}, {})
    for z in (np.array([800.0, -5.0]), np.array([-800.0, -900.0])):
        host = param.natural(z)["weights"]
        with jax.enable_x64(True):
            traced = np.asarray(param.natural(jnp.asarray(z))["weights"])
        assert np.all(np.isfinite(host))
        np.testing.assert_allclose(host, traced, atol=1e-15)


def test_depth_slopes_are_the_same_in_numpy_and_jax():
    rng = np.random.default_rng(5)
    depth = 500.0 + np.cumsum(rng.normal(0.0, 1.0, (9, 11)), axis=1)
    host = depth_slopes(depth)
    with jax.enable_x64(True):
        traced = depth_slopes(jnp.asarray(depth))
    for a, b in zip(host, traced):
        assert not isinstance(a, jax.Array)
        np.testing.assert_allclose(a, np.asarray(b), rtol=1e-13)


def test_sum_of_gaussians_is_the_same_in_numpy_and_jax():
    # The report draws the fitted profile through the NumPy path.
    rng = np.random.default_rng(7)
    r = np.linspace(0.0, 9.0, 50)
    variances = rng.uniform(0.05, 9.0, 4)
    for weights in (rng.uniform(0.0, 1.0, 4), rng.uniform(0.0, 1.0, (4, 3))):
        host = sum_of_gaussians(r, weights, variances)
        assert isinstance(host, np.ndarray) and host.shape == r.shape + weights.shape[1:]
        with jax.enable_x64(True):
            traced = jax.jit(sum_of_gaussians)(jnp.asarray(r), jnp.asarray(weights), jnp.asarray(variances))
        np.testing.assert_allclose(host, np.asarray(traced), rtol=1e-13, atol=0.0)


def test_log_unknowns_beyond_the_limit_map_to_the_limit_in_both_paths():
    """An unknown the data bound on one side only (maxdd where no slope reaches it)
    can walk off; ``exp`` would overflow (float64 near 710, the returned float32
    near 88). Beyond ``LOG_LIMIT`` the value is the limit's, finite, the same on
    the host and traced, and its derivative 0."""
    from invsss.estimator.parametrisation import LOG_LIMIT

    param = _param(np.random.default_rng(5))
    first, _ = param.layout()["maxdd"]
    ratio, _ = param.layout()["gain_ratio"]
    far = np.zeros(param.size)
    far[first], far[ratio] = 837.0, -900.0
    at_limit = far.copy()
    at_limit[first], at_limit[ratio] = LOG_LIMIT, -LOG_LIMIT
    host, limit = param.natural(far), param.natural(at_limit)
    with jax.enable_x64(True):
        traced = eqx.filter_jit(lambda p, u: p.natural(u))(param, jnp.asarray(far))
        slope = jax.grad(lambda u: param.natural(u)["maxdd"])(jnp.asarray(far))
    for name in ("maxdd", "gain_ratio"):
        assert np.all(np.isfinite(host[name])) and np.all(np.asarray(host[name], np.float32) < np.inf), name
        np.testing.assert_array_equal(host[name], limit[name])
        np.testing.assert_allclose(np.asarray(traced[name]), host[name], rtol=1e-15)
    assert float(host["maxdd"]) > 1e20 and float(host["gain_ratio"][0]) < 1e-20
    assert float(slope[first]) == 0.0
