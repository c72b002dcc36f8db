"""The light-aware terms (docs/model.md, section 8): JAX against a SciPy reference of
the definition, gradients against finite differences, and inputs checked in one
line. The twin, the fits, the command line and sweeps are tested in the folders of
their layers (test_light_terms.py in each)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_light_terms, shift_image
from tests.forward._lit_scenes import H, W, light_terms_scene

pytestmark = pytest.mark.usefixtures("float64")


def _reference(blurred, depth, mask, light, normal, params, shift, grazing, incidence=0.0):
    """Section 8 written out with SciPy's bilinear interpolation (clamped coordinates)."""
    ddy, ddx = np.gradient(depth)
    L, c, delta = float(params.sss_level), float(params.correction), float(params.maxdd)
    s_x = L / (depth + c * np.minimum(np.abs(ddx), delta))
    s_y = L / (depth + c * np.minimum(np.abs(ddy), delta))
    dx, dy = shift * s_x * -light[..., 0], shift * s_y * light[..., 1]
    rows, cols = np.meshgrid(np.arange(H, dtype=float), np.arange(W, dtype=float), indexing="ij")
    coords = [np.clip(rows - dy, 0, H - 1), np.clip(cols - dx, 0, W - 1)]
    moved = np.stack([ndimage.map_coordinates(blurred[..., k], coords, order=1) for k in range(3)], -1)
    moved *= (1.0 + grazing * (1.0 - np.clip(normal[..., 2], 0.0, 1.0)))[..., None]
    cos_incidence = np.einsum("hwc,hwc->hw", normal, light)
    moved *= (1.0 + incidence * (1.0 - np.clip(cos_incidence, 0.0, 1.0)))[..., None]
    return blurred + mask[..., None] * (moved - blurred)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("shift, grazing, incidence", [(3.0, 0.3, 0.0), (-1.5, -0.4, 0.5), (0.0, 0.7, -0.3),
                                                        (0.0, 0.0, 0.8)])
def test_render_matches_the_definition(seed, shift, grazing, incidence):
    image, depth, mask, light, normal, params = light_terms_scene(seed)
    terms = LightTerms(shift=shift, grazing=grazing, incidence=incidence)
    out = invsss.render(image, depth, mask, params, light_terms=terms,
                        light_buffers=LightBuffers(normal=normal, light=light))
    blurred = np.asarray(invsss.render(image, depth, mask, params))
    expected = _reference(blurred, depth, mask, light, normal, params, shift, grazing, incidence)
    np.testing.assert_allclose(np.asarray(out), expected, rtol=0, atol=1e-12)
    # The terms do something (otherwise the comparison above would prove little);
    # a shift moves content by more than a pixel somewhere.
    assert np.max(np.abs(np.asarray(out) - blurred)) > 0.05


@pytest.mark.slow
def test_shift_moves_an_edge_away_from_the_light():
    # A vertical edge lit from the camera's left (l_x < 0): light travels right,
    # so the edge moves right by kappa * s_x pixels.
    image = np.zeros((6, 20, 1))
    image[:, 10:] = 1.0
    depth = np.full((6, 20), 400.0)
    light = np.zeros((6, 20, 3))
    light[..., 0], light[..., 2] = -0.6, 0.8
    params = invsss.SSSParams(400.0, 0.0, 1.0, [1.0], [1e-8])  # s = 1 px/mm, no blur
    out = invsss.render(image, depth, np.ones((6, 20)), params, light_terms=LightTerms(shift=2.5),
                        light_buffers=LightBuffers(light=light))
    row = np.asarray(out)[3, :, 0]
    # The 0.5 crossing moves from 9.5 to 9.5 + 2.5 * 0.6 = 11.
    crossing = np.interp(0.5, row, np.arange(20.0))
    assert crossing == pytest.approx(11.0, abs=1e-9)


def test_zero_terms_are_the_identity():
    image, depth, mask, light, normal, params = light_terms_scene()
    blurred = invsss.render(image, depth, mask, params)
    out = invsss.render(image, depth, mask, params, light_terms=LightTerms(),
                        light_buffers=LightBuffers(normal=normal, light=light))
    np.testing.assert_array_equal(np.asarray(out), np.asarray(blurred))


@pytest.mark.slow
def test_gradients_match_finite_differences():
    image, depth, mask, light, normal, params = light_terms_scene()
    blurred = jnp.asarray(invsss.render(image, depth, mask, params))
    buffers = LightBuffers(normal=jnp.asarray(normal), light=jnp.asarray(light))
    weights = jnp.asarray(np.random.default_rng(3).normal(size=(H, W, 3)))

    def f(x):
        p = invsss.SSSParams(x[2], params.correction, params.maxdd, params.weights, params.variances)
        out = apply_light_terms(blurred, jnp.asarray(depth), jnp.asarray(mask), p,
                                LightTerms(shift=x[0], grazing=x[1], incidence=x[3]), buffers)
        return jnp.sum(weights * out)

    # Away from integer sample positions (kinks of linear interpolation).
    x0 = jnp.asarray([1.37, 0.21, 810.0, -0.17])
    grad = np.asarray(jax.grad(f)(x0))
    for i, h in enumerate([1e-6, 1e-6, 1e-3, 1e-6]):
        e = np.zeros(4)
        e[i] = h
        fd = (float(f(x0 + e)) - float(f(x0 - e))) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=1e-5, abs=1e-8)
    assert np.all(np.abs(grad) > 1e-3)


@pytest.mark.slow
def test_shift_image_composes_with_jit_and_vmap():
    rng = np.random.default_rng(5)
    images = jnp.asarray(rng.uniform(size=(4, 7, 9, 2)))
    offset = jnp.asarray(rng.uniform(-1.5, 1.5, size=(7, 9, 2)))
    batched = jax.jit(jax.vmap(shift_image, in_axes=(0, None)))(images, offset)
    for k in range(4):
        np.testing.assert_allclose(np.asarray(batched[k]), np.asarray(shift_image(images[k], offset)), atol=1e-14)


class TestBadInput:
    def setup_method(self):
        self.image, self.depth, self.mask, self.light, self.normal, self.params = light_terms_scene()

    def _render(self, terms, buffers):
        return invsss.render(self.image, self.depth, self.mask, self.params, light_terms=terms,
                             light_buffers=buffers)

    def test_missing_buffer_is_named(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.light: the 'shift' term needs"):
            self._render(LightTerms(shift=1.0), LightBuffers(normal=self.normal))

    def test_no_buffers_at_all(self):
        with pytest.raises(invsss.InvalidInputError, match="light_buffers: light_terms need"):
            self._render(LightTerms(grazing=0.2), None)

    def test_wrong_shape(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.normal: expected shape \(12, 15, 3\)"):
            self._render(LightTerms(grazing=0.2), LightBuffers(normal=self.normal[..., :2]))

    def test_eight_bit_normals_are_refused(self):
        encoded = np.round((self.normal * 0.5 + 0.5) * 255)
        with pytest.raises(invsss.InvalidInputError, match="expected unit vectors.*decoded"):
            self._render(LightTerms(grazing=0.2), LightBuffers(normal=encoded))

    def test_nan_on_the_mask(self):
        light = self.light.copy()
        light[5, 5] = np.nan
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.light: NaN"):
            self._render(LightTerms(shift=1.0), LightBuffers(light=light))

    def test_grazing_gain_must_stay_positive(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\.grazing: expected a value > -1"):
            self._render(LightTerms(grazing=-1.0), LightBuffers(normal=self.normal))

    def test_zero_vectors_off_the_mask_are_accepted(self):
        light = self.light.copy()
        light[:2] = 0.0  # the rows the mask leaves out, as a renderer writes them
        out = self._render(LightTerms(shift=1.0), LightBuffers(light=light))
        assert np.all(np.isfinite(np.asarray(out)))
