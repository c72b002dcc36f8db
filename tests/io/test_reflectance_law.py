"""The ``law`` light term exported (invsss.io.export): the HLSL snippet, run as NumPy,
is the model's factor, and the law alone exports no after-blur constants."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightTerms, reflectance_law
from tests.forward._lit_scenes import LAW_PARAMS, law_scene
from tests.io._hlsl import hlsl_law_factor

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
def test_the_exported_law_is_the_model():
    source, key, _, mask, normal, light = law_scene(8)
    albedo = [0.93, 0.8, 0.55]
    constants = invsss.shader_constants(LAW_PARAMS, light_terms={"law": albedo, "law_strength": 0.7, "shift": 1.1})
    assert constants["lawAlbedo"] == albedo and constants["lightShift"] == 1.1
    assert constants["lawStrength"] == 0.7
    hlsl = invsss.to_hlsl(constants, prefix="sss_")
    assert "static const float sss_lawAlbedo[3] = { 0.93, 0.8, 0.55 };" in hlsl
    assert "float3 invsssKeyLightLaw(float3 normal, float3 toLight)" in hlsl

    law = hlsl_law_factor(hlsl, "invsssKeyLightLaw", constants)
    # The key light's factor at strength a: 1 + a (g - 1).
    expected = 1.0 + 0.7 * (np.asarray(reflectance_law(jnp.asarray(normal), jnp.asarray(light),
                                                       jnp.asarray(albedo))) - 1.0)
    for r, c in [(3, 4), (5, 9), (11, 14), (7, 0)]:
        n, l_ = normal[r, c].copy(), light[r, c].copy()
        if r == 7:
            l_ = -n  # the key light behind the surface: mu0 = 0
        wanted = expected[r, c] if r != 7 else 1.0 + 0.7 * (np.asarray(
            reflectance_law(jnp.asarray(n[None, None]), jnp.asarray(l_[None, None]), jnp.asarray(albedo)))[0, 0] - 1.0)
        np.testing.assert_allclose(law(n, l_), wanted, rtol=1e-12)


def test_only_the_law_exports_no_after_blur_constants():
    constants = invsss.shader_constants(LAW_PARAMS, light_terms=LightTerms(law=0.9))
    assert "lightShift" not in constants and len(constants["lawAlbedo"]) == 3
    assert constants["lawAlbedo"][0] == constants["lawAlbedo"][2] == pytest.approx(0.9)
    hlsl = invsss.to_hlsl(constants)
    assert "invsssKeyLightLaw" in hlsl and "invsssLightTerms" not in hlsl
