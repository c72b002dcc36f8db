"""The ``fill`` light term exported (invsss.io.export): the other lights' factor in the
HLSL snippet, run as NumPy, is the model's, and it is written only with the fill."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightTerms, reflectance_law
from tests.forward._lit_scenes import LAW_PARAMS, fill_scene
from tests.io._hlsl import hlsl_law_factor

pytestmark = pytest.mark.usefixtures("float64")


def test_the_exported_fill_factor_is_the_model():
    _, _, _, _, normal, _, fill_light = fill_scene(5)
    albedo = [0.93, 0.8, 0.55]
    constants = invsss.shader_constants(LAW_PARAMS, light_terms={"law": albedo, "law_strength": 0.7, "fill": 0.4})
    assert constants["lawFillStrength"] == 0.4 and constants["lawStrength"] == 0.7
    hlsl = invsss.to_hlsl(constants, prefix="sss_")
    assert "float3 invsssOtherLightLaw(float3 normal, float3 toLight)" in hlsl
    assert "float3 invsssKeyLightLaw(float3 normal, float3 toLight)" in hlsl
    # Without the fill neither the constant nor the function is written.
    plain = invsss.shader_constants(LAW_PARAMS, light_terms={"law": albedo, "law_strength": 0.7})
    assert "lawFillStrength" not in plain and "invsssOtherLightLaw" not in invsss.to_hlsl(plain)
    # The same through a LightTerms.
    assert invsss.shader_constants(LAW_PARAMS, light_terms=LightTerms(law=albedo, fill=0.4))["lawFillStrength"] == 0.4

    factor = hlsl_law_factor(hlsl, "invsssOtherLightLaw", constants)
    expected = 1.0 + 0.4 * (np.asarray(reflectance_law(jnp.asarray(normal), jnp.asarray(fill_light),
                                                       jnp.asarray(albedo))) - 1.0)
    for r, c in [(3, 4), (5, 9), (11, 14)]:
        np.testing.assert_allclose(factor(normal[r, c], fill_light[r, c]), expected[r, c], rtol=1e-12)
