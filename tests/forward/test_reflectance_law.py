"""The ``law`` light term (docs/model.md, section 8): the key light's part of the source
under Chandrasekhar's reflectance law. JAX against a NumPy reference of the
definition, gradients against finite differences, and inputs checked in one line.
The twin, the export, the fits, the command line and sweeps are tested in the
folders of their layers (test_reflectance_law.py in each)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_law, reflectance_law

from tests.forward._lit_scenes import (
    LAW_PARAMS,
    H,
    W,
    law_reference,
    law_scene,
    unit,
)

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
@pytest.mark.parametrize("albedo", [0.9, [0.95, 0.8, 0.6]])
def test_render_applies_the_law_to_the_source_before_the_blur(albedo):
    source, key, depth, mask, normal, light = law_scene()
    buffers = LightBuffers(normal=normal, light=light, key=key)
    out = invsss.render(source, depth, mask, LAW_PARAMS, light_terms=LightTerms(law=albedo), light_buffers=buffers)
    expected = invsss.render(law_reference(source, key, mask, normal, light, albedo), depth, mask, LAW_PARAMS)
    np.testing.assert_allclose(np.asarray(out), np.asarray(expected), rtol=1e-12, atol=1e-13)
    # The law changes the image: the test would pass for no term at all otherwise.
    assert np.abs(np.asarray(out) - np.asarray(invsss.render(source, depth, mask, LAW_PARAMS))).max() > 0.01


def test_the_law_leaves_head_on_light_and_the_other_lights_alone():
    source, key, depth, mask, normal, light = law_scene(1)
    facing = np.zeros_like(normal)
    facing[..., 2] = 1.0
    # Light arriving and leaving along the normal: the law's gain is 1.
    same = apply_law(source, mask, 0.7, LightBuffers(facing, facing, key))
    np.testing.assert_allclose(np.asarray(same), source, atol=1e-14)
    # No key light: nothing for the law to act on.
    none = apply_law(source, mask, 0.7, LightBuffers(normal, light, np.zeros_like(key)))
    np.testing.assert_array_equal(np.asarray(none), source)
    # Off the mask the source is kept.
    changed = np.asarray(apply_law(source, mask, 0.7, LightBuffers(normal, light, key)))
    np.testing.assert_array_equal(changed[:2], source[:2])
    assert np.abs(changed[3:] - source[3:]).max() > 0.05


@pytest.mark.slow
def test_the_law_has_the_known_limits_and_order_in_albedo():
    # Low albedo: single scattering, the Lommel-Seeliger law 1 / (mu + mu0);
    # albedo near 1: H(x) -> 1 + 2x, the conservative medium. In between, the lower
    # the albedo, the more light comes back at oblique incidence relative to
    # head-on (less of it is absorbed on the way out from near the surface).
    rng = np.random.default_rng(9)
    normal = unit(rng.normal(size=(4, 5, 3)) + [0.0, 0.0, 2.0])
    light = unit(rng.normal(size=(4, 5, 3)) + [0.0, 0.0, 1.0])
    mu = np.clip(normal[..., 2], 0.0, 1.0)
    mu0 = np.clip(np.einsum("hwk,hwk->hw", normal, light), 0.0, 1.0)
    # The law is trusted where both cosines reach 0.1, faded to Lambert (1) below.
    trust = np.clip(np.minimum(normal[..., 2], np.einsum("hwk,hwk->hw", normal, light)) / 0.1, 0.0, 1.0)
    assert 0 < np.mean(trust == 1.0) < 1  # both kinds of pixel are tested

    def gain(w):
        return np.asarray(reflectance_law(jnp.asarray(normal), jnp.asarray(light), w))[..., 0]

    def faded(law):
        return 1.0 + trust * (np.where(trust > 0, law, 1.0) - 1.0)

    with np.errstate(divide="ignore", invalid="ignore"):
        np.testing.assert_allclose(gain(1e-12), faded(2.0 / (mu + mu0)), rtol=1e-9)
        # sqrt(1 - w) is floored at 1e-6, which moves H by up to about 2e-6 relative.
        np.testing.assert_allclose(gain(1.0 - 1e-12), faded((1 + 2 * mu) * (1 + 2 * mu0) / (mu + mu0) / 4.5),
                                   rtol=1e-5)
    facing = np.zeros((1, 3, 3))
    facing[..., 2] = 1.0
    oblique = unit(np.array([[[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.95, 0.0, 0.312]]]))
    ratios = {w: np.asarray(reflectance_law(jnp.asarray(facing), jnp.asarray(oblique), w))[0, :, 0]
              for w in (0.5, 0.9, 0.99)}
    assert all(r[0] == pytest.approx(1.0) for r in ratios.values())
    assert ratios[0.5][2] > ratios[0.9][2] > ratios[0.99][2]
    assert ratios[0.5][1] > ratios[0.9][1] > ratios[0.99][1]


@pytest.mark.slow
def test_gradients_match_finite_differences():
    source, key, depth, mask, normal, light = law_scene(2)
    buffers = LightBuffers(normal=jnp.asarray(normal), light=jnp.asarray(light), key=jnp.asarray(key))
    weights = jnp.asarray(np.random.default_rng(3).normal(size=(H, W, 3)))

    def f(w):
        return jnp.sum(weights * invsss.render(source, depth, mask, LAW_PARAMS, light_terms=LightTerms(law=w),
                                               light_buffers=buffers))

    w0 = jnp.asarray([0.93, 0.8, 0.55])
    grad = np.asarray(jax.grad(f)(w0))
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1e-6
        fd = (float(f(w0 + e)) - float(f(w0 - e))) / 2e-6
        assert grad[i] == pytest.approx(fd, rel=1e-6)
    assert np.all(np.abs(grad) > 1e-3)


def test_the_law_composes_with_jit_and_vmap():
    source, key, _, mask, normal, light = law_scene(4)
    albedos = jnp.asarray([[0.9, 0.8, 0.7], [0.5, 0.5, 0.5]])
    batched = jax.jit(jax.vmap(lambda w: apply_law(source, mask, w, LightBuffers(normal, light, key))))(albedos)
    for k in range(2):
        one = apply_law(source, mask, albedos[k], LightBuffers(normal, light, key))
        np.testing.assert_allclose(np.asarray(batched[k]), np.asarray(one), atol=1e-14)


class TestBadInput:
    def setup_method(self):
        self.source, self.key, self.depth, self.mask, self.normal, self.light = law_scene()

    def _render(self, terms, buffers):
        return invsss.render(self.source, self.depth, self.mask, LAW_PARAMS, light_terms=terms, light_buffers=buffers)

    def test_missing_key_is_named(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: the 'law' term needs this buffer"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light))

    def test_key_of_another_size_or_channel_count(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: expected shape \(12, 15, 3\)"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light, self.key[..., :1]))
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: expected shape"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light, self.key[:5]))

    def test_nan_in_the_key(self):
        key = self.key.copy()
        key[4, 4, 1] = np.nan
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: NaN"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light, key))

    @pytest.mark.parametrize("albedo", [1.0, 0.0, -0.2, [0.9, 1.3, 0.5], float("nan")])
    def test_albedo_outside_zero_to_one(self, albedo):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\.law: expected an albedo in \(0, 1\)"):
            self._render(LightTerms(law=albedo), LightBuffers(self.normal, self.light, self.key))

    def test_one_albedo_per_channel(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\.law: expected one albedo or one per image"):
            self._render(LightTerms(law=[0.9, 0.8]), LightBuffers(self.normal, self.light, self.key))
