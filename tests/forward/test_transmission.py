"""The ``transmission`` light term (issue 48): HDRP's transmittance of Burley's profile and
its wrapped back-side lighting, added to the source before the blur; the identity at a
tint of 0, gradients against differences, and the buffers' checks."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms
from invsss.forward.transmission import (
    TRANSMISSION_WRAP,
    apply_transmission,
    burley_transmittance,
    wrapped_back_lighting,
)
from invsss.validation import InvalidInputError
from tests.forward._backlit_scenes import backlit_dome

PARAMS = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])


def _burley(r, d=1.0):
    """Burley's normalised profile (Christensen & Burley 2015), per unit area."""
    return (np.exp(-r / d) + np.exp(-r / (3.0 * d))) / (8.0 * np.pi * d * r)


@pytest.mark.parametrize("x", [0.0, 0.3, 1.0, 2.5, 6.0])
def test_transmittance_is_the_profile_integrated_over_the_far_plane(x, float64):
    # HDRP's comment on ComputeTransmittanceDisney: Int{0, inf} 2 pi r R(sqrt(r^2 + t^2)) dr.
    if x == 0.0:
        expected = 1.0  # the normalised profile's whole energy
    else:
        expected, _ = integrate.quad(lambda r: 2.0 * np.pi * r * _burley(np.hypot(r, x)), 0.0, np.inf)
    assert float(burley_transmittance(x)) == pytest.approx(expected, rel=1e-7)


def test_transmittance_matches_hdrps_arithmetic(float64):
    # HDRP writes it with exp2 and LOG2_E, the volume albedo being a quarter of the tint.
    log2_e = 1.0 / np.log(2.0)
    shape, thickness, tint = np.array([0.5, 1.0, 2.0]), 1.7, np.array([0.9, 0.4, 0.2])
    exp_13 = np.exp2(log2_e * (-1.0 / 3.0) * thickness * shape)
    hdrp = 0.25 * tint * (exp_13 * (exp_13 * exp_13 + 3.0))
    np.testing.assert_allclose(tint * np.asarray(burley_transmittance(shape * thickness)), hdrp, rtol=1e-12)


def test_back_lighting_wraps_fifteen_degrees():
    def at(cosine):
        normal = np.array([[[0.0, 0.0, 1.0]]])
        light = np.array([[[np.sqrt(1.0 - cosine**2), 0.0, cosine]]])
        return float(wrapped_back_lighting(normal, light)[0, 0])

    assert TRANSMISSION_WRAP == pytest.approx(np.cos(np.radians(75.0)))
    assert at(-1.0) == pytest.approx(1.0 / (1.0 + TRANSMISSION_WRAP))  # straight behind
    assert at(0.0) == pytest.approx(TRANSMISSION_WRAP / (1.0 + TRANSMISSION_WRAP) ** 2)  # edge-on: still lit
    assert at(TRANSMISSION_WRAP + 1e-6) == 0.0 and at(0.9) == 0.0  # the front side within 75 degrees


def test_a_tint_of_zero_is_the_identity_and_the_light_joins_before_the_blur():
    source, depth, mask, buffers = backlit_dome()
    plain = np.asarray(invsss.render(source, depth, mask, PARAMS))
    off = np.asarray(invsss.render(source, depth, mask, PARAMS, light_terms=LightTerms(transmission=0.0),
                                   light_buffers=buffers))
    np.testing.assert_array_equal(off, plain)
    terms = LightTerms(transmission=0.7, thickness_scale=0.2)
    on = np.asarray(invsss.render(source, depth, mask, PARAMS, light_terms=terms, light_buffers=buffers))
    lit = np.asarray(apply_transmission(source, mask, terms, buffers))
    np.testing.assert_allclose(on, np.asarray(invsss.render(lit, depth, mask, PARAMS)), rtol=1e-6, atol=1e-7)
    # It adds light where the key light is behind, most where the part is thin.
    added = (lit - source)[..., 0]
    back = mask * (np.asarray(buffers.normal) @ np.asarray(buffers.light)[0, 0] < 0.0)
    assert added[back > 0].min() > 0.0
    thin, thick = np.asarray(buffers.thickness) < 5.0, np.asarray(buffers.thickness) > 30.0
    assert added[(back > 0) & thin].mean() > 3.0 * added[(back > 0) & thick].mean()


def test_gradients_agree_with_differences(float64):
    source, depth, mask, buffers = backlit_dome(channels=3)
    weights = jnp.asarray(np.random.default_rng(0).normal(size=source.shape))

    def loss(x):
        terms = LightTerms(transmission=x[:3], thickness_scale=x[3])
        return jnp.sum(weights * invsss.render(source, depth, mask, PARAMS, light_terms=terms, light_buffers=buffers))

    x0 = jnp.array([0.8, 0.5, 0.3, 0.15])
    grad = np.asarray(jax.grad(loss)(x0))
    step = 1e-6
    numeric = [(float(loss(x0.at[i].add(step))) - float(loss(x0.at[i].add(-step)))) / (2 * step) for i in range(4)]
    np.testing.assert_allclose(grad, numeric, rtol=1e-6)
    assert np.all(np.abs(grad) > 1e-3)


def test_buffers_and_values_are_checked_in_one_line():
    source, depth, mask, buffers = backlit_dome()
    terms = LightTerms(transmission=0.5)
    no_thickness = LightBuffers(buffers.normal, buffers.light, key_irradiance=buffers.key_irradiance)
    with pytest.raises(InvalidInputError, match="light_buffers.thickness: the 'transmission' term needs this buffer"):
        invsss.render(source, depth, mask, PARAMS, light_terms=terms, light_buffers=no_thickness)
    for bad, message in ((-1.0, "expected a thickness >= 0 mm"), (np.nan, "NaN or infinite thickness")):
        thickness = np.array(buffers.thickness)
        thickness[16, 16] = bad
        broken = LightBuffers(buffers.normal, buffers.light, thickness=thickness,
                              key_irradiance=buffers.key_irradiance)
        with pytest.raises(InvalidInputError, match=f"light_buffers.thickness: {message}"):
            invsss.render(source, depth, mask, PARAMS, light_terms=terms, light_buffers=broken)
    with pytest.raises(InvalidInputError, match=r"light_buffers.thickness: expected shape \(32, 32\)"):
        LightBuffers(thickness=np.zeros((4, 4))).checked((32, 32), mask)
    with pytest.raises(InvalidInputError, match="light_terms.transmission: expected a tint >= 0"):
        LightTerms(transmission=-0.1).check()
    with pytest.raises(InvalidInputError, match="light_terms.thickness_scale: expected one number > 0"):
        LightTerms(transmission=0.1, thickness_scale=0.0).check()
    with pytest.raises(InvalidInputError, match="light_terms.transmission: expected one tint or one per image"):
        invsss.render(source, depth, mask, PARAMS, light_terms=LightTerms(transmission=[0.1, 0.2]),
                      light_buffers=buffers)
