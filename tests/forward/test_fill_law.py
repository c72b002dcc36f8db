"""The ``fill`` light term (docs/model.md, section 8): the key light's reflectance law
applied with the same albedo to the other lights' part of the source ``S - K``, with
their direction ``fill_light`` and a strength of its own. JAX against the definition
written out in NumPy, and gradients against finite differences. The twin, the
exported factor, the fits, the command line and sweeps are tested in the folders of
their layers (test_fill_law.py in each)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_law

from tests.forward._lit_scenes import LAW_PARAMS, fill_scene, law_reference

pytestmark = pytest.mark.usefixtures("float64")


def _expected(source, key, mask, normal, light, fill_light, albedo, strength, fill):
    """S + m a K (g(n, l) - 1) + m b (S - K) (g(n, l_f) - 1), from the NumPy reference of the law."""
    keyed = law_reference(source, key, mask, normal, light, albedo, strength)
    # law_reference adds m s P (g - 1) for a part P: here P = S - K, s = b.
    return keyed + law_reference(np.zeros_like(source), source - key, mask, normal, fill_light, albedo, fill)


@pytest.mark.parametrize("albedo", [0.9, [0.95, 0.8, 0.6]])
def test_the_fill_is_the_law_on_the_other_lights(albedo):
    source, key, _, mask, normal, light, fill_light = fill_scene()
    buffers = LightBuffers(normal, light, key, fill_light)
    out = np.asarray(apply_law(source, mask, albedo, buffers, 0.8, 0.6))
    expected = _expected(source, key, mask, normal, light, fill_light, albedo, 0.8, 0.6)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-13)
    # The fill changes the image beyond the key light's law (else the test would
    # pass for a fill that did nothing).
    key_only = np.asarray(apply_law(source, mask, albedo, buffers, 0.8))
    assert np.abs(out - key_only).max() > 0.02
    # Off the mask nothing changes.
    np.testing.assert_array_equal(out[:2], source[:2])


@pytest.mark.slow
def test_render_applies_the_fill_before_the_blur():
    source, key, depth, mask, normal, light, fill_light = fill_scene(1)
    buffers = LightBuffers(normal, light, key, fill_light)
    terms = LightTerms(law=[0.95, 0.8, 0.6], law_strength=0.7, fill=1.2)
    out = invsss.render(source, depth, mask, LAW_PARAMS, light_terms=terms, light_buffers=buffers)
    lit = _expected(source, key, mask, normal, light, fill_light, [0.95, 0.8, 0.6], 0.7, 1.2)
    np.testing.assert_allclose(np.asarray(out), np.asarray(invsss.render(lit, depth, mask, LAW_PARAMS)),
                               rtol=1e-12, atol=1e-13)


@pytest.mark.slow
def test_gradients_match_finite_differences():
    source, key, depth, mask, normal, light, fill_light = fill_scene(3)
    buffers = LightBuffers(*(jnp.asarray(x) for x in (normal, light, key, fill_light)))
    weights = jnp.asarray(np.random.default_rng(3).normal(size=source.shape))

    def f(x):
        terms = LightTerms(law=x[:3], law_strength=0.9, fill=x[3])
        return jnp.sum(weights * invsss.render(source, depth, mask, LAW_PARAMS, light_terms=terms, light_buffers=buffers))

    x0 = jnp.asarray([0.93, 0.8, 0.55, 0.7])
    grad = np.asarray(jax.grad(f)(x0))
    for i in range(4):
        e = np.zeros(4)
        e[i] = 1e-6
        fd = (float(f(x0 + e)) - float(f(x0 - e))) / 2e-6
        assert grad[i] == pytest.approx(fd, rel=1e-6)
    assert abs(grad[3]) > 1e-3
