"""Shader constants: a shader built from the exported numbers alone must render what
:func:`invsss.render` renders, and the HLSL text must carry exactly those numbers."""

from __future__ import annotations

import json
import re

import jax
import numpy as np
import pytest

from invsss import InvalidInputError, SSSParams, render
from invsss.io.export import export_params, shader_constants, to_hlsl, to_json
from tests.io._hlsl import parse_hlsl
from tests.io._params_files import params_file  # noqa: F401 (fixture)


@pytest.fixture
def x64():
    with jax.enable_x64(True):
        yield


def make_scene(h=8, w=9, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 60.0 + 12.0 * np.sin(x / 2.1 + 0.3) * np.cos(y / 2.7 - 0.2) + 0.3 * rng.standard_normal((h, w))
    image = rng.uniform(0.05, 1.0, (h, w, 3))
    mask = np.ones((h, w))
    mask[:, 0] = 0.0
    mask[1, 2:5] = [0.3, 0.6, 0.9]
    return image, depth, mask


# ------------------------------------------------- a "shader" that sees only the constants


def sample(image, positions, axis):
    """Linear interpolation, clamp-to-edge, along rows (axis 1) or columns (axis 0):
    what a bilinear sampler with clamp addressing returns at pixel coordinates."""
    if axis == 0:
        return sample(image.transpose(1, 0, 2), positions.transpose(1, 0, 2), 1).transpose(1, 0, 2, 3)
    h, w, _ = image.shape
    u = np.clip(positions, 0.0, w - 1.0)
    i0 = np.floor(u).astype(int)
    i1 = np.minimum(i0 + 1, w - 1)
    a = (u - i0)[..., None]
    rows = np.arange(h)[:, None, None]
    return (1.0 - a) * image[rows, i0] + a * image[rows, i1]


def stretch(c, depth):
    ddy, ddx = np.gradient(depth)
    s_x = c["sssLevel"] / (depth + c["correction"] * np.minimum(np.abs(ddx), c["maxdd"]))
    s_y = c["sssLevel"] / (depth + c["correction"] * np.minimum(np.abs(ddy), c["maxdd"]))
    return s_x, s_y


def seven_tap_pass(c, image, mask, s, width, axis):
    coord = np.arange(image.shape[axis], dtype=np.float64)
    centre = coord[None, :] if axis == 1 else coord[:, None]
    footprint = s * width
    positions = centre[..., None] + footprint[..., None] * np.asarray(c["tapOffsets"])
    blurred = np.einsum("hwkc,k->hwc", sample(image, positions, axis), np.asarray(c["tapWeights"]))
    return mask[..., None] * blurred + (1.0 - mask[..., None]) * image


def shade_sog(c, image, depth, mask):
    s_x, s_y = stretch(c, depth)
    layer = image
    out = np.zeros_like(image)
    for width, blend in zip(c["passWidths"], c["blendFactors"]):
        layer = seven_tap_pass(c, layer, mask, s_x, width, axis=1)
        layer = seven_tap_pass(c, layer, mask, s_y, width, axis=0)
        out = out + np.asarray(blend) * (layer - out)  # lerp(out, layer, blend)
    return out


def shade_thesis(c, image, depth, mask):
    s_x, s_y = stretch(c, depth)
    out = image
    for s, axis in ((s_x, 1), (s_y, 0)):
        for width in c["passWidths"]:
            out = seven_tap_pass(c, out, mask, s, width, axis)
    return out


def shade_separable(c, image, depth, mask):
    """iryoku/separable-sss's SSSSBlurPS: centre tap first, then the others."""
    kernel = np.asarray(c["kernel"])
    scale = c["sssLevel"] / depth
    out = image
    for axis in (1, 0):
        coord = np.arange(image.shape[axis], dtype=np.float64)
        centre = coord[None, :] if axis == 1 else coord[:, None]
        positions = centre[..., None] + scale[..., None] * kernel[1:, 3]
        blurred = kernel[0, :3] * out + np.einsum("hwnc,nc->hwc", sample(out, positions, axis), kernel[1:, :3])
        out = mask[..., None] * blurred + (1.0 - mask[..., None]) * out
    return out


SOG_CASES = {
    # unsorted variances, per-channel weights with a channel whose first layers weigh 0
    "rgb": ([[0.2, 0.0, 0.9], [0.6, 0.0, 0.1], [0.3, 0.8, 0.4]], [2.5, 0.4, 1.1], "jimenez"),
    "shared": ([0.5, 0.2, 0.3], [0.9, 3.0, 0.3], "thesis"),
}


@pytest.mark.parametrize("case", sorted(SOG_CASES))
def test_sog_constants_reproduce_render(x64, case):
    weights, variances, taps = SOG_CASES[case]
    image, depth, mask = make_scene()
    p = SSSParams(61.3, 2.7, 2.3, weights, variances)
    c = shader_constants(p, "sog", tap_weights=taps)
    assert c["variances"] == sorted(variances)
    want = np.asarray(render(image, depth, mask, p, "sog", tap_weights=taps))
    np.testing.assert_allclose(shade_sog(c, image, depth, mask), want, rtol=1e-12, atol=1e-14)
    assert np.abs(want - image).max() > 0.05


def test_sog_widths_weights_and_blend_factors():
    p = SSSParams(900.0, 0.0, 1.0, [0.0, 0.5, 0.5], [2.0, 0.5, 4.5])
    c = shader_constants(p, tap_weights="thesis")
    c_w = np.sqrt(sum(w * (k / 3.0) ** 2 for w, k in zip(c["tapWeights"], range(-3, 4))))
    np.testing.assert_allclose(c["tapSpread"], 0.61008, atol=1e-5)
    np.testing.assert_allclose(c["passWidths"], np.sqrt([0.5, 1.5, 2.5]) / c_w, rtol=1e-12)
    np.testing.assert_allclose(c["layerWeights"], [0.5, 0.0, 0.5], rtol=1e-7)
    np.testing.assert_allclose(c["blendFactors"], [1.0, 0.0, 0.5], rtol=1e-7)
    # A first layer of weight 0: the accumulator just holds it until a weighed layer replaces it.
    q = SSSParams(900.0, 0.0, 1.0, [0.0, 0.5, 0.5], [0.5, 2.0, 4.5])
    np.testing.assert_allclose(shader_constants(q)["blendFactors"], [1.0, 1.0, 0.5], rtol=1e-7)


def test_thesis_constants_reproduce_render(x64):
    image, depth, mask = make_scene()
    p = SSSParams(61.3, 2.7, 2.3, [0.5, 0.5], [2.5, 0.4])
    c = shader_constants(p, "thesis")
    assert c["tapWeights"] == pytest.approx([0.1053, 0.1402, 0.1664, 0.1762, 0.1664, 0.1402, 0.1053])
    np.testing.assert_allclose(c["passWidths"], np.sqrt([2.5, 0.4]) / c["tapSpread"], rtol=1e-12)
    want = np.asarray(render(image, depth, mask, p, "thesis"))
    np.testing.assert_allclose(shade_thesis(c, image, depth, mask), want, rtol=1e-12, atol=1e-14)


def test_thesis_listing_width_is_seven_pixels():
    # tap spread of the thesis weights, sqrt(sum_k W_k t_k^2), t_k = k / 3
    c_w = np.sqrt(2 * (0.1053 * 1.0 + 0.1402 * 4 / 9 + 0.1664 / 9))
    c = shader_constants(SSSParams(1.0, 0.0, 1.0, [1.0], [(7 * c_w) ** 2]), "thesis")
    assert c["passWidths"][0] == pytest.approx(7.0, rel=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("weights", [[0.4, 0.6], [[0.2, 0.5, 0.9], [0.6, 0.4, 0.1]]], ids=["shared", "rgb"])
def test_separable_constants_reproduce_render(x64, weights):
    image, depth, mask = make_scene()
    p = SSSParams(150.0, 2.7, 2.3, weights, [0.4, 2.5])
    c = shader_constants(p, "separable", taps=11, strength=0.8)
    assert c["numTaps"] == len(c["kernel"]) == len(c["kernelOffsets"]) == 11
    assert c["kernel"][0][3] == pytest.approx(0.0, abs=1e-12)  # centre first, like iryoku
    np.testing.assert_allclose(np.asarray(c["kernelWeights"]).sum(axis=0), 1.0, rtol=1e-12)
    want = np.asarray(render(image, depth, mask, p, "separable", taps=11, strength=0.8))
    np.testing.assert_allclose(shade_separable(c, image, depth, mask), want, rtol=1e-12, atol=1e-14)


# ------------------------------------------------------------------- text formats


@pytest.mark.parametrize(
    "model,weights",
    [("sog", [[0.2, 0.5, 0.9], [0.6, 0.4, 0.1]]), ("sog", [0.3, 0.7]), ("thesis", [0.3, 0.7]), ("separable", [0.3, 0.7])],
    ids=["sog-rgb", "sog", "thesis", "separable"],
)
def test_hlsl_declares_every_constant(model, weights):
    c = shader_constants(SSSParams(640.0, 3.5, 0.02, weights, [1e-3, 2.2]), model, taps=17)
    text = to_hlsl(c)
    header = [line for line in text.splitlines() if line.startswith("//")]
    assert f"// model: {model}" in header
    assert any(line.startswith("// units:") and "scene units" in line for line in header)
    parsed = parse_hlsl(text)
    numeric = {k: v for k, v in c.items() if not isinstance(v, str)}
    assert set(parsed) == set(numeric)
    for name, value in numeric.items():
        kind, got = parsed[name]
        if isinstance(value, int):
            assert kind == "int" and got == value
            continue
        want = np.asarray(value, dtype=np.float64)
        assert kind == ("float" if want.ndim < 2 else f"float{want.shape[1]}"), name
        np.testing.assert_allclose(np.asarray(got), want, rtol=1e-7, atol=0, err_msg=name)
    # per-channel data must come out as float3, one per layer or tap
    if model == "sog":
        assert parsed["blendFactors"][0] == ("float3" if np.ndim(weights) == 2 else "float")
    if model == "separable":
        assert parsed["kernel"][0] == "float4" and parsed["kernelWeights"][0] == "float3"


def test_hlsl_prefix_and_rejects_what_it_cannot_write():
    text = to_hlsl({"model": "sog", "sssLevel": 2.0, "passWidths": [1.0]}, prefix="SSS_")
    assert set(parse_hlsl(text)) == {"SSS_sssLevel", "SSS_passWidths"}
    with pytest.raises(InvalidInputError, match="ragged"):
        to_hlsl({"ragged": [[1.0, 2.0], [1.0, 2.0, 3.0]]})
    with pytest.raises(InvalidInputError, match="bad"):
        to_hlsl({"bad": float("nan")})


def test_json_round_trips():
    c = shader_constants(SSSParams(640.0, 3.5, 0.02, [[0.2, 0.5, 0.9], [0.6, 0.4, 0.1]], [0.7, 2.2]))
    assert json.loads(to_json(c)) == c


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"params": {"sss_level": 1.0}}, "params"),
        ({"model": "dipole"}, "model"),
        ({"tap_weights": "box"}, "tap_weights"),
        ({"tap_weights": [0.5, 0.5]}, "tap_weights"),
        ({"params": SSSParams(1.0, 0.0, 1.0, np.ones((2, 2)), [0.5, 1.0])}, "weights"),
        ({"model": "separable", "taps": 16}, "taps"),
        ({"model": "separable", "strength": [0.5, 1.0, 1.0]}, "strength"),
    ],
)
def test_invalid_arguments(kwargs, match):
    kwargs = {"params": SSSParams(1.0, 0.0, 1.0, [0.5, 0.5], [0.5, 1.0]), **kwargs}
    with pytest.raises(InvalidInputError, match=match) as info:
        shader_constants(**kwargs)
    assert "\n" not in str(info.value)


# ------------------------------------------------------------------------- files


def test_export_params_reads_model_from_file_and_writes(params_file, tmp_path):
    out = tmp_path / "constants.json"
    text = export_params(params_file, out, "json")
    assert out.read_text() == text
    c = json.loads(text)
    assert c["model"] == "thesis" and c["sssLevel"] == 612.345678901
    np.testing.assert_allclose(c["passWidths"][0], np.sqrt(0.123456789012) / c["tapSpread"], rtol=1e-15)
    # An explicit model overrides the file's.
    assert json.loads(export_params(params_file, model="sog"))["model"] == "sog"
    with pytest.raises(InvalidInputError, match="format"):
        export_params(params_file, format="glsl")


def test_light_terms_export_constants_and_the_snippet(tmp_path):
    import invsss

    params = invsss.SSSParams(900.0, 2.0, 0.5, [0.3, 0.7], [2.0, 0.5])
    plain = invsss.shader_constants(params)
    lit = invsss.shader_constants(params, light_terms={"shift": 1.25, "grazing": -0.2, "stderr": {}})
    assert {k: v for k, v in lit.items() if k not in ("lightShift", "grazingGain", "incidenceGain")} == plain
    # A term the record does not hold is written as 0 (off).
    assert (lit["lightShift"], lit["grazingGain"], lit["incidenceGain"]) == (1.25, -0.2, 0.0)
    hlsl = invsss.to_hlsl(lit, prefix="sss_")
    assert "static const float sss_lightShift = 1.25;" in hlsl
    assert "float3 invsssLightTerms(" in hlsl and "sss_grazingGain * (1.0 - saturate(normal.z))" in hlsl
    assert "sss_incidenceGain * (1.0 - saturate(dot(normal, toLight)))" in hlsl
    terms = invsss.LightTerms(incidence=0.35)  # float32 outside x64: written as the object holds it
    assert invsss.shader_constants(params, light_terms=terms)["incidenceGain"] == float(terms.incidence) != 0.0
    with pytest.raises(invsss.InvalidInputError, match="light_terms.incidence: expected a value > -1"):
        invsss.shader_constants(params, light_terms={"incidence": -1.0})
    # Every constant the snippet reads is declared above it.
    snippet = hlsl[hlsl.index("float3 invsssLightTerms"):]
    for name in re.findall(r"\bsss_\w+", snippet):
        assert f"static const float {name} " in hlsl
    assert "invsssLightTerms" not in invsss.to_hlsl(plain)
    with pytest.raises(invsss.InvalidInputError, match="light_terms.grazing: expected a value > -1"):
        invsss.shader_constants(params, light_terms={"grazing": -1.5})
    # Misuse a library user meets: one-line errors naming the argument.
    with pytest.raises(invsss.InvalidInputError, match=r"constants: expected the dict of invsss.shader_constants, got SSSParams"):
        invsss.to_hlsl(params)
    with pytest.raises(invsss.InvalidInputError, match=r"prefix: expected letters, digits and '_'"):
        invsss.to_hlsl(plain, prefix="my sss ")
    with pytest.raises(invsss.InvalidInputError, match=r"params_json_path: expected the path of a params file, got SSSParams"):
        invsss.export_params(params, format="hlsl")
    # A misspelt term is refused, not exported switched off.
    with pytest.raises(invsss.InvalidInputError, match="light_terms: unknown key 'shfit' \\(did you mean 'shift'\\?\\)"):
        invsss.shader_constants(params, light_terms={"shfit": 0.5})
    # A params file with a fit's light_terms record exports them.
    path = tmp_path / "params.json"
    invsss.write_params(path, {"sss_level": 900.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0],
                               "variances": [2.0], "light_terms": {"shift": 1.1, "stderr": {"shift": 0.1}}})
    assert "static const float lightShift = 1.1;" in invsss.export_params(path, format="hlsl")
