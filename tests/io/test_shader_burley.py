"""The ``burley`` reference shader (invsss/shaders/invsss_burley.hlsl, docs/renderer.md),
built by glslangValidator and run on Vulkan through wgpu, against
``invsss.render(model="burley")`` in float32: within 1e-4 of the image's peak on
fran_front (RGB, a different ``d`` per channel; and one ``d`` for every channel with a
feathered mask) and on pt_face_940 (grey, the ``d`` its fit reaches), with the pixels
off the mask copied bit for bit; and each deliberately wrong constant, or wrong line of
a port, missing by more than 10 times that bound.

Skipped like tests/io/test_shader.py (the device fixture is in tests/io/conftest.py)
without glslangValidator, wgpu or a Vulkan device.
"""

from __future__ import annotations

import json
import math
import shutil

import jax
import numpy as np
import pytest

import invsss.shaders
from invsss import InvalidInputError, SSSParams, render
from invsss.io.export import shader_constants, to_hlsl
from invsss.shaders import SHADER_DIR, SHADER_FILES, run_shader
from tests.io._shaders import DATA, TOLERANCE, pair, relative_error

SHADER = "invsss_burley.hlsl"


def _burley(level, d):
    """Burley parameters: ``sss_level`` and one ``d`` (mm) or one per channel (the weights are unused)."""
    return SSSParams(level, 0.0, 1.0, [1.0] * len(d), [x * x for x in d])


def _fran_truth():
    return json.loads((DATA / "fran_front" / "truth.json").read_text())


def _feathered(mask):
    """The mask averaged over 3 x 3 pixels (edge-padded): fractions on a 2-pixel rim."""
    padded = np.pad(mask, 1, mode="edge")
    h, w = mask.shape
    return sum(padded[i:i + h, j:j + w] for i in range(3) for j in range(3)).astype(np.float32) / 9.0


def _case(name):
    """image, depth, mask and burley parameters of one comparison."""
    if name == "pt_face_940":
        image, depth, mask = pair("pt_face_940")
        # Grey; sss_level the camera's focal length in pixels, d = 0.72 mm as its
        # burley fit reaches (docs/model.md, section 5, the model comparison).
        focal = json.loads((DATA / "pt_face_940" / "scene.json").read_text())["focal_px"]
        return image, depth, mask, _burley(focal, [0.72])
    image, depth, mask = pair("fran_front")
    level = _fran_truth()["sss_level"]
    if name == "fran_rgb":  # a d per channel, of the size skin has (mm), red widest
        return image, depth, mask, _burley(level, [1.2, 0.6, 0.35])
    # one d for the three channels, and a mask with fractions on its rim
    return image, depth, _feathered(mask), _burley(level, [0.8])


CASES = ("fran_rgb", "fran_one_d_feathered", "pt_face_940")
_CACHE = {}


def _prepared(name):
    """The case and invsss.render's float32 image of it (computed once per process)."""
    if name not in _CACHE:
        image, depth, mask, params = _case(name)
        want = np.asarray(render(image, depth, mask, params, "burley"))
        assert want.dtype == np.float32
        _CACHE[name] = image, depth, mask, params, want
    return _CACHE[name]


# ------------------------------------------------------------------ the comparison


@pytest.mark.slow
@pytest.mark.parametrize("case", CASES)
def test_burley_shader_matches_render(device, case):
    image, depth, mask, params, want = _prepared(case)
    messages = []
    got = run_shader(image, depth, mask, to_hlsl(shader_constants(params, "burley")), "burley",
                     adapter_name=device, messages=messages)
    error = relative_error(got, want)
    print(f"burley {case} on {device}: max |shader - render| / peak = {error:.2e}")
    assert error < TOLERANCE
    # The comparison means something: the blur moved the image by far more.
    assert relative_error(image, want) > 100 * TOLERANCE
    # Off the mask the source comes through bit for bit, as render's mask blend gives.
    off = mask == 0
    assert off.any() and np.array_equal(got[off], image[off])
    # and the compiler had nothing to say.
    assert messages == [(SHADER, "BurleyDiskCS", "")], messages


# ----------------------------------------------- wrong constants and wrong ports


def _scale_d(channel, factor):
    def breaker(c):
        d = list(c["shapeParameters"])
        d[channel] *= factor
        c["shapeParameters"] = d
    return breaker


def _directions(angle_step):
    def breaker(c):
        angles = [angle_step * j for j in range(c["numSamples"])]
        c["sampleCos"] = [math.cos(a) for a in angles]
        c["sampleSin"] = [math.sin(a) for a in angles]
    return breaker


def _radii_at(shift, n=32):
    """Unit radii where Burley's radial CDF is ``(j + shift) / n`` (Cardano, as docs/model.md gives it)."""
    u = 1.0 - (np.arange(n) + shift) / n
    root = np.sqrt(4.0 * u * u + 1.0)
    return (-3.0 * np.log(np.cbrt(2.0 * u + root) + np.cbrt(2.0 * u - root))).tolist()


#: Mistakes in the constants (a function of the exported dict) or in a port of the
#: shader (a line of invsss_burley.hlsl replaced), each on fran_rgb.
BREAKS = {
    "green d 5 % off": ("constants", _scale_d(1, 1.05)),
    "red (widest) d 5 % off": ("constants", _scale_d(0, 1.05)),
    "golden angle as 2 pi / phi (the spiral mirrored)": ("constants", _directions(2 * math.pi / ((1 + 5**0.5) / 2))),
    "directions evenly spaced, not the golden angle": ("constants", _directions(2 * math.pi / 32)),
    "radii at quantiles j / N, not (j + 1/2) / N": ("constants", lambda c: c.update(sampleRadii=_radii_at(0.0))),
    "sssLevel for depth in metres (1000x)": ("constants", lambda c: c.update(sssLevel=c["sssLevel"] / 1000.0)),
    "radii in pixels, not in units of d": (
        "source", ("float radiusPx = r * scale;", "float radiusPx = sampleRadii[j];")),
    "the depth term left out": (
        "source", ("float rho = sqrt(r * r + dz * dz);", "float rho = r;")),
    "no mask weight": (
        "source", ("float3 weight = profile / pdf * s.mask;", "float3 weight = profile / pdf;")),
    "the pdf left out": (
        "source", ("float3 weight = profile / pdf * s.mask;", "float3 weight = profile * s.mask;")),
}


@pytest.mark.slow
@pytest.mark.parametrize("mistake", sorted(BREAKS))
def test_wrong_burley_constants_are_caught(device, mistake, tmp_path, monkeypatch):
    image, depth, mask, params, want = _prepared("fran_rgb")
    constants = shader_constants(params, "burley")
    kind, change = BREAKS[mistake]
    if kind == "constants":
        broken = json.loads(json.dumps(constants))
        change(broken)
        assert broken != constants
        constants = broken
    else:  # the shader as a wrong port would have it
        for name in SHADER_FILES:
            shutil.copy(SHADER_DIR / name, tmp_path / name)
        old, new = change
        text = (tmp_path / SHADER).read_text()
        assert text.count(old) == 1, old
        (tmp_path / SHADER).write_text(text.replace(old, new))
        monkeypatch.setattr(invsss.shaders, "SHADER_DIR", tmp_path)
    got = run_shader(image, depth, mask, to_hlsl(constants), "burley", adapter_name=device)
    error = relative_error(got, want)
    print(f"burley, {mistake}, on {device}: max |shader - render| / peak = {error:.2e}")
    # Caught with room to spare: at least 10x the acceptance bound.
    assert error > 10 * TOLERANCE, mistake


# ------------------------------------------------------- the export and the files


def test_burley_export_has_what_the_shader_reads():
    with jax.enable_x64(True):  # SSSParams rounds to float32 otherwise, as export_params avoids
        rgb = shader_constants(_burley(600.0, [1.2, 0.6, 0.35]), "burley")
        grey = shader_constants(_burley(600.0, [0.72]), "burley")
    assert rgb["numShapeParameters"] == 3 and grey["numShapeParameters"] == 1
    np.testing.assert_allclose(rgb["shapeParameters"], [1.2, 0.6, 0.35], rtol=1e-15)
    assert rgb["numSamples"] == len(rgb["sampleRadii"]) == len(rgb["sampleCos"]) == len(rgb["sampleSin"]) == 32
    assert "passWidths" not in rgb["units"] and "sampleRadii" in rgb["units"]
    text = to_hlsl(rgb)
    for name in ("sssLevel", "shapeParameters", "numShapeParameters", "numSamples", "sampleRadii", "sampleCos",
                 "sampleSin"):
        assert f" {name}" in text, name
    with pytest.raises(InvalidInputError, match=r"^params\.variances: a burley export takes d\^2 .* got 2$"):
        shader_constants(_burley(600.0, [1.0, 2.0]), "burley")
