"""Constants for a real-time shader: fitted parameters in the form a renderer uses.

A fitted :class:`~invsss.forward.params.SSSParams` describes the model; a shader needs
the numbers derived from it: per-pass widths, the 7 tap offsets and weights,
the running blend factors that accumulate the ``sog`` layers, or the N-tap
kernel of the ``separable`` model. :func:`shader_constants` computes them,
:func:`to_hlsl` and :func:`to_json` write them out, and :func:`export_params`
does both for a params JSON file (``invsss export``).

How a shader uses the constants (docs/model.md, sections 2, 3 and 5):

* stretch ``s = sssLevel / (depth + correction * min(|ddx(depth)|, maxdd))`` in
  pixels per scene unit (``ddy`` for vertical passes);
* a 7-tap pass with width ``passWidths[i]`` (scene units) has footprint
  ``f = s * passWidths[i]`` pixels and samples at ``pixel + tapOffsets[k] * f``
  with weight ``tapWeights[k]``;
* ``sog``: pass pair ``i`` (horizontal, then vertical) blurs the previous
  layer into layer ``i``; ``out = lerp(out, layer_i, blendFactors[i])`` after
  each pair gives ``sum_i w_i B_i / sum_i w_i`` (Jimenez 2009's accumulation);
* ``thesis``: all horizontal passes, then all vertical passes, chained; the
  last pass is the output (Listing 4.1 is ``passWidths = {7}``);
* ``separable``: one horizontal and one vertical pass of ``numTaps`` taps at
  ``pixel + kernelOffsets[n] * sssLevel / depth`` weighted per channel by
  ``kernelWeights[n]`` (no correction term in this model). ``kernel`` holds the
  same numbers as iryoku/separable-sss's ``float4 kernel[]``: ``rgb`` weight and
  ``a`` offset, centre tap first.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping

import jax
import numpy as np

from ..forward.light_terms import LAW_TRUST
from ..forward.models import MODEL_NAMES, get_model, resolve_tap_weights
from ..forward.params import SSSParams
from ..forward.passes import TAP_OFFSETS, tap_spread
from ..forward.passes import tap_weights as tap_weight_set
from ..forward.screen_space import separable_kernel
from ..forward.transmission import TRANSMISSION_WRAP
from ..validation import InvalidInputError
from . import read_params
from .light_constants import light_constants
from .params_file import warn_filled_for_model
from .shader_export import shader_files, write_shader
from .writing import write_texts_atomic

__all__ = ["EXPORT_FORMATS", "shader_constants", "to_hlsl", "to_json", "export_params", "write_shader",
           "shader_files", "scale_to_resolution"]

#: Output formats of :func:`export_params` and ``invsss export``; ``hdrp`` and
#: ``unreal`` are the engines' profile assets (:mod:`invsss.io.engine_profiles`, issue 34).
EXPORT_FORMATS = ("json", "hlsl", "hdrp", "unreal")

_SCALE_UNITS = (
    "depth and profile in scene units (mm recommended); sssLevel in pixels per scene unit "
    "at unit depth; "
)
_PASS_UNITS = _SCALE_UNITS + (
    "passWidths in scene units, footprint_px = s * passWidths[i]; tapOffsets in footprints"
)
_KERNEL_UNITS = _SCALE_UNITS + (
    "kernelOffsets in scene units, tap at pixel + offset * sssLevel / depth "
    "(correction and maxdd unused)"
)


def _floats(x) -> list:
    """Nested lists of Python floats (what JSON and the HLSL writer take)."""
    return np.asarray(x, dtype=np.float64).tolist()


def _layer_weights(weights: np.ndarray, order: np.ndarray, name: str) -> np.ndarray:
    """Weights sorted like the layers, normalised to sum 1 (per channel): (K,) or (K, 3)."""
    w = weights[order]
    if w.ndim == 2 and w.shape[1] == 1:
        w = w[:, 0]
    if w.ndim == 2 and w.shape[1] != 3:
        raise InvalidInputError(
            f"{name}: weights must have 1 or 3 columns (channels) to export, got shape {weights.shape}",
            field=name,
        )
    return w / w.sum(axis=0)


def _blend_factors(w: np.ndarray) -> np.ndarray:
    """``w_i / sum_{j<=i} w_j``: the lerp factor that folds layer ``i`` into the running mean.

    Where no weight has arrived yet (the cumulative sum is 0) the factor is 1:
    the accumulator then just holds the current layer, and the first layer with
    a positive weight (factor 1 too) replaces it.
    """
    cumulative = np.cumsum(w, axis=0)
    safe = np.where(cumulative > 0, cumulative, 1.0)
    return np.where(cumulative > 0, w / safe, 1.0)


def shader_constants(
    params: SSSParams, model: str = "sog", tap_weights=None, taps: int = 17, strength: float = 1.0,
    light_terms=None,
) -> dict:
    """Everything a real-time shader needs to reproduce :func:`~invsss.render`.

    Parameters
    ----------
    params : SSSParams
        Weights of shape (K,), (K, 1) or (K, 3).
    model : {"sog", "thesis", "separable", "burley"}
        A name from :data:`invsss.forward.models.MODEL_NAMES`.
    tap_weights : {"jimenez", "thesis"} or 7 numbers, optional
        7-tap weight set of ``sog`` and ``thesis`` (default: the model's
        ``default_tap_weights``). Not used by ``separable``.
    taps : int
        ``separable`` only: number of kernel taps (odd; 11, 17 or 25 in Jimenez's code).
    strength : float
        ``separable`` only: blend of the kernel with the identity.
    light_terms : LightTerms or mapping, optional
        The light-aware terms of docs/model.md, section 8 (a fit's
        ``light_terms`` record works too): adds ``lightShift`` (kappa, scene
        units), ``grazingGain`` (gamma) and ``incidenceGain`` (beta), 0 for a
        term not in use, and :func:`to_hlsl` then adds the function that
        applies them after the blur (:data:`LIGHT_TERMS_HLSL`). With the
        ``law`` term it adds ``lawAlbedo`` (``w`` for red, green and blue; one
        ``w`` is repeated), and :func:`to_hlsl` the key light's BRDF factor for
        the lighting pass (:data:`LAW_HLSL`); the three constants after the blur
        are then written only when one of those terms is in use. With the
        ``fill`` term it adds ``lawFillStrength``, and :func:`to_hlsl` the same
        factor for the other lights (``invsssOtherLightLaw``).

    Returns
    -------
    dict
        JSON-ready (Python floats, ints, strings and lists). Always ``model``,
        ``units``, ``sssLevel``, ``correction``, ``maxdd``. For ``sog`` and
        ``thesis`` also ``numPasses`` (K), ``tapOffsets`` (7), ``tapWeights``
        (7), ``tapSpread`` (``c_W``), ``variances`` (K, in pass order) and
        ``passWidths`` (K, scene units): ``sqrt(v_i - v_{i-1}) / c_W`` over the
        sorted variances for ``sog``, ``sqrt(v_i) / c_W`` in the given order for
        ``thesis``. ``sog`` adds ``layerWeights`` and ``blendFactors``, (K,) or
        (K, 3). ``separable`` gives ``numTaps``, ``strength``, ``kernelOffsets``
        (N, scene units), ``kernelWeights`` (N, 3) and ``kernel`` (N, 4).

    Raises
    ------
    InvalidInputError
        Not an SSSParams, values that break its constraints, an unknown model or
        tap weight set, weights with a channel count other than 1 or 3, an even
        or too small ``taps``, a ``strength`` that is not one number.

    Examples
    --------
    >>> import invsss
    >>> p = invsss.SSSParams(900.0, 2.0, 0.5, [0.3, 0.7], [2.0, 0.5])
    >>> c = shader_constants(p)
    >>> [round(x, 4) for x in c["passWidths"]]
    [2.0412, 3.5355]
    >>> [round(x, 4) for x in c["blendFactors"]]
    [1.0, 0.3]
    """
    if not isinstance(params, SSSParams):
        raise InvalidInputError(f"params: expected invsss.SSSParams, got {type(params).__name__}")
    params.check()
    entry = get_model(model)
    weights = np.asarray(params.weights, dtype=np.float64)
    variances = np.asarray(params.variances, dtype=np.float64)
    constants = {
        "model": entry.name,
        "units": _KERNEL_UNITS if entry.layout == "kernel" else _PASS_UNITS,
        "sssLevel": float(params.sss_level),
        "correction": float(params.correction),
        "maxdd": float(params.maxdd),
    }
    options = {"tap_weights": tap_weights, "taps": taps, "strength": strength}
    constants.update(_RECIPES[entry.layout](entry, weights, variances, options))
    if light_terms is not None:
        constants.update(light_constants(light_terms))
    return constants


#: The HLSL function :func:`to_hlsl` appends when the constants hold the light-aware
#: terms (docs/model.md, section 8). Call it in the final pass on the blurred
#: image; ``stretch`` is (s_x, s_y) of that pixel, as the blur passes compute it.
LIGHT_TERMS_HLSL = """
// Light-aware terms (invsss docs/model.md, section 8), applied to the blurred
// image in the final pass. toLight and normal are unit vectors in view space
// with x right, y up and z towards the camera (negate z for a +z-forward view
// space); texel is 1 / resolution; the sampler is bilinear, clamp to edge.
float3 invsssLightTerms(Texture2D blurred, SamplerState linearClamp, float2 uv, float2 texel,
                        float2 stretch, float3 toLight, float3 normal)
{
    float2 travel = float2(-toLight.x, toLight.y);        // image axes: x right, rows down
    float2 delta = {prefix}lightShift * stretch * travel;  // pixels
    float3 shifted = blurred.SampleLevel(linearClamp, uv - delta * texel, 0).rgb;
    return shifted * (1.0 + {prefix}grazingGain * (1.0 - saturate(normal.z)))
                   * (1.0 + {prefix}incidenceGain * (1.0 - saturate(dot(normal, toLight))));
}
"""


#: The HLSL :func:`to_hlsl` appends when the constants hold the ``law`` term
#: (docs/model.md, section 8), before the key light's factor (:data:`LAW_FACTOR_HLSL`),
#: the diffuse BRDF factor for the lighting pass, before the blur.
LAW_HLSL = """
// The key light's reflectance law (invsss docs/model.md, section 8): in the
// lighting pass, multiply the key light's Lambertian diffuse term
// (albedo * irradiance * saturate(dot(normal, toLight))) by this factor; the
// other lights stay Lambertian unless the fill term's factor follows, and the blur
// passes do not change. normal and toLight are unit vectors in view space, z
// towards the camera. The factor fades to 1 where the normal faces (nearly) away
// from the camera or the light, and lawStrength 0 makes it 1 everywhere.
float3 invsssHapkeH(float x, float3 w)
{
    return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * sqrt(max(1.0 - w, 1e-12)));
}
"""

#: One light's law factor, ``1 + a t (f_w / f_w(1, 1) - 1)``: LAW_NAME and
#: LAW_STRENGTH are filled in for the key light (``lawStrength``) and, with the
#: ``fill`` term, for the other lights (``lawFillStrength``).
LAW_FACTOR_HLSL = """
float3 LAW_NAME(float3 normal, float3 toLight)
{
    float3 w = float3({prefix}lawAlbedo[0], {prefix}lawAlbedo[1], {prefix}lawAlbedo[2]);
    float nDotL = dot(normal, toLight);
    float mu = saturate(normal.z);
    float mu0 = saturate(nDotL);
    float trust = saturate(min(normal.z, nDotL) / LAW_TRUST_PLACEHOLDER);
    float3 headOn = invsssHapkeH(1.0, w) * invsssHapkeH(1.0, w) / 2.0;
    float3 ratio = invsssHapkeH(mu, w) * invsssHapkeH(mu0, w) / max(mu + mu0, 1e-6) / headOn;
    return 1.0 + {prefix}LAW_STRENGTH * trust * (ratio - 1.0);
}
"""

#: The HLSL :func:`to_hlsl` appends when the constants hold the ``transmission`` term
#: (docs/model.md, section 8): the light a key light behind a thin part adds, before the blur.
TRANSMISSION_HLSL = """
// Light from the key light that crossed a thin part (invsss docs/model.md, section 8):
// in the lighting pass, add this to the diffuse lighting that the blur spreads.
// thickness: mm the key light travels inside the skin (0 where the surface faces it);
// keyIrradiance: the albedo times the key light's unshadowed irradiance on a surface
// facing it, in the same units as the lighting; normal and toLight: unit vectors in
// view space, z towards the camera. As HDRP's ComputeTransmittanceDisney with its
// wrapped back cosine (15 degrees).
float3 invsssTransmittedLight(float thickness, float3 keyIrradiance, float3 normal, float3 toLight)
{
    float third = exp(-{prefix}thicknessScale * thickness / 3.0);
    float transmittance = 0.25 * third * (third * third + 3.0);
    float wrap = WRAP_PLACEHOLDER;
    float back = saturate((-dot(normal, toLight) + wrap) / ((1.0 + wrap) * (1.0 + wrap)));
    float3 tint = float3({prefix}transmissionTint[0], {prefix}transmissionTint[1], {prefix}transmissionTint[2]);
    return tint * transmittance * back * keyIrradiance;
}
"""

#: The comment :func:`to_hlsl` puts before the other lights' factor (the ``fill`` term).
FILL_LAW_HLSL = """
// The same law for every other light (the fill term): in the lighting pass,
// multiply each other light's Lambertian diffuse term by this factor, with
// that light's own toLight. lawFillStrength 0 would make it 1 everywhere.
#define INVSSS_OTHER_LIGHT_LAW 1"""


def _pass_constants(entry, weights, variances, options) -> dict:
    """The 7-tap layouts: tap set, per-pass widths, and for ``layered`` the blend."""
    tap_weights = resolve_tap_weights(entry, options["tap_weights"])
    # Derived numbers in float64 whatever the session's default: a shader gets
    # them rounded once, to its own float32, not twice.
    with jax.enable_x64(True):
        try:
            w_taps = tap_weight_set(tap_weights, np.float64)
        except ValueError as err:
            raise InvalidInputError(str(err)) from None
        c_w = float(tap_spread(w_taps))
    plan = entry.pass_plan(variances, c_w, np)
    v = variances if plan.order is None else variances[plan.order]
    # One width per Gaussian: in both layouts the vertical passes are one per
    # Gaussian, in pass order, and each horizontal pass has the same width.
    widths = plan.widths[np.asarray(plan.axes) == 0]
    constants = {
        "numPasses": int(v.size),
        "tapWeightSet": tap_weights if isinstance(tap_weights, str) else "custom",
        "tapOffsets": list(TAP_OFFSETS),
        "tapWeights": _floats(w_taps),
        "tapSpread": c_w,
        "variances": _floats(v),
        "passWidths": _floats(widths),
    }
    if entry.layout == "layered":
        layer_weights = _layer_weights(weights, plan.order, "params")
        constants["layerWeights"] = _floats(layer_weights)
        constants["blendFactors"] = _floats(_blend_factors(layer_weights))
    return constants


def _kernel_constants(entry, weights, variances, options) -> dict:
    return _separable_constants(weights, variances, options["taps"], options["strength"])


def _separable_constants(weights, variances, taps, strength) -> dict:
    if not isinstance(taps, int) or isinstance(taps, bool):
        raise InvalidInputError(f"taps: expected an odd integer >= 3, got {taps!r}")
    if np.ndim(strength) != 0 or not math.isfinite(float(strength)):
        raise InvalidInputError(f"strength: expected one finite number, got {strength!r}")
    if weights.ndim == 2 and weights.shape[1] not in (1, 3):
        raise InvalidInputError(
            f"params: weights must have 1 or 3 columns (channels) to export, got shape {weights.shape}"
        )
    with jax.enable_x64(True):
        jax_offsets, jax_kernel = separable_kernel(weights, variances, taps, float(strength))
        offsets = np.asarray(jax_offsets, dtype=np.float64)
        kernel = np.asarray(jax_kernel, dtype=np.float64)
    kernel_rgb = np.broadcast_to(kernel, (taps, 3))
    # iryoku/separable-sss's float4 kernel: rgb weight, a offset, centre tap first
    # and then the others in increasing order.
    centre = taps // 2
    order = [centre] + [n for n in range(taps) if n != centre]
    iryoku = np.concatenate([kernel_rgb, offsets[:, None]], axis=1)[order]
    return {
        "numTaps": int(taps),
        "strength": float(strength),
        "kernelOffsets": _floats(offsets),
        "kernelWeights": _floats(kernel_rgb),
        "kernel": _floats(iryoku),
    }


#: How each layout of :data:`invsss.forward.models.LAYOUTS` is exported.
# --- issue 34: the burley model's disk (invsss.forward.burley_screen_space) ---
def _disk_constants(entry, weights, variances, options) -> dict:
    """The ``burley`` layout: shape parameters and the fixed sample pattern.

    ``shapeParameters`` holds Burley's ``d`` (scene units), one for every
    channel or one per red, green and blue, and ``numShapeParameters`` their
    count (HLSL has no length of an array). Sample ``j`` of ``numSamples`` sits
    at ``pixel + max(d) * sampleRadii[j] * sssLevel / depth * (sampleCos[j],
    sampleSin[j])``; ``invsss/shaders/invsss_burley.hlsl`` gives the weights.
    ``units`` replaces the 7-tap layouts' text, which does not apply.
    """
    from ..forward.burley_screen_space import sample_pattern

    if variances.ndim != 1 or variances.size not in (1, 3):
        raise InvalidInputError(
            f"params.variances: a burley export takes d^2 for every channel (1 value) or for red, green "
            f"and blue (3), got {variances.size}"
        )
    x, cos_a, sin_a = sample_pattern()
    units = _SCALE_UNITS + (
        "shapeParameters (Burley's d) in scene units; sampleRadii in units of max(d), sample j at "
        "pixel + max(d) * sampleRadii[j] * sssLevel / depth * (sampleCos[j], sampleSin[j]) "
        "(correction and maxdd unused)"
    )
    return {"units": units, "shapeParameters": _floats(np.sqrt(variances)),
            "numShapeParameters": int(variances.size), "numSamples": int(x.size),
            "sampleRadii": _floats(x), "sampleCos": _floats(cos_a), "sampleSin": _floats(sin_a)}


_RECIPES = {"layered": _pass_constants, "chained": _pass_constants, "kernel": _kernel_constants,
            "disk": _disk_constants}
# --- end issue 34 ---


# ------------------------------------------------------------------ writers


def _literal(x: float, name: str) -> str:
    # repr is the shortest text that reads back to the same double; HLSL reads
    # C-style literals ("0.5", "1e-05", "3.0") and rounds them to float.
    if not math.isfinite(x):
        raise InvalidInputError(f"{name}: cannot write the non-finite number {x!r} as an HLSL constant", field=name)
    return repr(float(x))


def _hlsl_vector(row, name: str) -> str:
    return f"float{len(row)}(" + ", ".join(_literal(x, name) for x in row) + ")"


def _hlsl_declaration(name: str, value) -> str:
    if isinstance(value, bool):
        raise InvalidInputError(f"{name}: booleans have no HLSL constant form here", field=name)
    if isinstance(value, int):
        return f"static const int {name} = {value};"
    if isinstance(value, float):
        return f"static const float {name} = {_literal(value, name)};"
    if isinstance(value, (list, tuple)) and value:
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
            body = ", ".join(_literal(x, name) for x in value)
            return f"static const float {name}[{len(value)}] = {{ {body} }};"
        widths = {len(row) if isinstance(row, (list, tuple)) else None for row in value}
        if len(widths) == 1 and widths <= {2, 3, 4}:
            (width,) = widths
            body = ",\n    ".join(_hlsl_vector(row, name) for row in value)
            return f"static const float{width} {name}[{len(value)}] = {{\n    {body}\n}};"
    raise InvalidInputError(
        f"{name}: expected a number, a list of numbers or a list of 2-4 vectors, got {value!r}",
        field=name,
    )


def to_hlsl(constants: dict, prefix: str = "") -> str:
    """HLSL ``static const`` declarations for the constants of :func:`shader_constants`.

    Numbers become ``float``, integer counts ``int``, lists ``float[N]`` and
    lists of 3 (4) numbers ``float3[N]`` (``float4[N]``). String entries
    (model, units, tap weight set) go into the comment header. ``prefix`` is
    prepended to every name, to keep clear of a shader's own identifiers; it must
    make them identifiers (letters, digits, ``_``). The reference shader of
    :func:`write_shader` reads the names without a prefix.

    Examples
    --------
    >>> print(to_hlsl({"model": "sog", "sssLevel": 900.0, "passWidths": [1.5, 2.0]}))
    // invsss shader constants
    // model: sog
    static const float sssLevel = 900.0;
    static const float passWidths[2] = { 1.5, 2.0 };
    <BLANKLINE>
    """
    if not isinstance(constants, Mapping):
        raise InvalidInputError(
            f"constants: expected the dict of invsss.shader_constants, got {type(constants).__name__} "
            "(for parameters, to_hlsl(shader_constants(params)))"
        )
    if not isinstance(prefix, str) or not (prefix + "x").isascii() or not (prefix + "x").isidentifier():
        raise InvalidInputError(
            f"prefix: expected letters, digits and '_' (not starting with a digit), got {prefix!r}"
        )
    lines = ["// invsss shader constants"]
    for key, value in constants.items():
        if isinstance(value, str):
            lines.append(f"// {key}: {value}")
    for key, value in constants.items():
        if not isinstance(value, str):
            lines.append(_hlsl_declaration(prefix + key, value))
    text = "\n".join(lines) + "\n"
    if "lightShift" in constants:
        text += LIGHT_TERMS_HLSL.replace("{prefix}", prefix)
    if "lawAlbedo" in constants:
        factors = [("invsssKeyLightLaw", "lawStrength", "")]
        if "lawFillStrength" in constants:
            factors.append(("invsssOtherLightLaw", "lawFillStrength", FILL_LAW_HLSL))
        text += LAW_HLSL
        for name, strength, comment in factors:
            text += comment + LAW_FACTOR_HLSL.replace("LAW_NAME", name).replace("LAW_STRENGTH", strength)
        text = text.replace("{prefix}", prefix).replace("LAW_TRUST_PLACEHOLDER", repr(LAW_TRUST))
    if "transmissionTint" in constants:
        text += TRANSMISSION_HLSL.replace("{prefix}", prefix).replace("WRAP_PLACEHOLDER", repr(TRANSMISSION_WRAP))
    return text


def to_json(constants: dict) -> str:
    """The constants as an indented JSON object (numbers round-trip exactly)."""
    return json.dumps(constants, indent=2) + "\n"


def scale_to_resolution(constants: dict, factor: float) -> dict:
    """The constants for an image ``factor`` times as wide and high as the one the fit saw.

    The stretch factors are per pixel (docs/renderer.md, "Another resolution"): at
    ``factor`` times the resolution a length on the skin covers ``factor`` times
    the pixels and a depth slope per pixel is ``1 / factor`` times as steep, so
    ``sssLevel`` and ``correction`` are multiplied by ``factor`` and ``maxdd``
    divided by it; then every footprint in pixels is ``factor`` times the
    fitted one. Pass widths, taps, weights, kernels and the light terms are in
    scene units or dimensionless and stay as they are.

    Examples
    --------
    >>> c = scale_to_resolution({"sssLevel": 600.0, "correction": 800.0, "maxdd": 0.5}, 2.0)
    >>> c["sssLevel"], c["correction"], c["maxdd"]
    (1200.0, 1600.0, 0.25)
    """
    factor = float(factor)
    if not math.isfinite(factor) or factor <= 0:
        raise InvalidInputError(f"factor: expected a positive number, got {factor!r}")
    out = dict(constants)
    out["sssLevel"] = constants["sssLevel"] * factor
    out["correction"] = constants["correction"] * factor
    out["maxdd"] = constants["maxdd"] / factor
    return out


def export_params(
    params_json_path, out_path=None, format: str = "json", *, model: str | None = None,
    tap_weights=None, taps: int = 17, strength: float = 1.0, with_shader: bool = False, engine: dict | None = None,
    overwrite: bool = False,
) -> str:
    """Read a params JSON file and export its shader constants.

    Parameters
    ----------
    params_json_path : str or os.PathLike
        A params file (:func:`invsss.io.read_params`); its ``model`` and
        ``tap_weights`` entries are used unless given here.
    out_path : str or os.PathLike, optional
        Where to write (atomically: the whole file or nothing); nothing is
        written when omitted. An existing file is refused unless ``overwrite``.
    format : {"json", "hlsl", "hdrp", "unreal"}
        ``hdrp`` and ``unreal`` write a ``burley`` fit as the engine's profile
        asset (:func:`invsss.io.engine_profiles.engine_profile`, JSON).
    engine : dict, optional
        ``hdrp``/``unreal`` only: keyword arguments of
        :func:`~invsss.io.engine_profiles.engine_asset` (``mm_per_unit``,
        ``albedo``, ``world_scale``, ``accept_assumed``, ``thickness_map_mm``,
        ``thickness_range_mm``).
    model, tap_weights, taps, strength
        As in :func:`shader_constants`; ``model`` and ``tap_weights`` override the file.
    with_shader : bool
        Also write the model's reference shader beside ``out_path``
        (:func:`write_shader`; its files and those of the fit's light terms);
        needs ``format="hlsl"`` and ``out_path``. The constants and the shader
        files are checked together before any is written, and none is written
        when one cannot be.
    overwrite : bool
        Replace ``out_path`` and shader files that are already there
        (``invsss export --overwrite``); otherwise an existing one is refused.

    Returns
    -------
    str
        The exported text.

    Examples
    --------
    >>> import os, tempfile, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "params.json")
    >>> invsss.write_params(path, {"sss_level": 900.0, "correction": 0.0, "maxdd": 1.0,
    ...                            "weights": [1.0], "variances": [2.0], "model": "thesis"})
    >>> hlsl = invsss.export_params(path, format="hlsl")
    >>> [line for line in hlsl.splitlines() if "passWidths" in line and "static" in line]
    ['static const float passWidths[1] = { 2.318071425053519 };']
    """
    if not isinstance(params_json_path, (str, os.PathLike)):
        raise InvalidInputError(
            f"params_json_path: expected the path of a params file, got {type(params_json_path).__name__} "
            "(for parameters in memory, to_hlsl(shader_constants(params)) or to_json(...))"
        )
    if format not in EXPORT_FORMATS:
        raise InvalidInputError(f"format: expected one of {', '.join(EXPORT_FORMATS)}, got {format!r}")
    if with_shader and (format != "hlsl" or out_path is None):
        raise InvalidInputError("with_shader: the shader needs format 'hlsl' and an output file (--out) to sit beside")
    # Read in float64 so the file's numbers reach the constants unrounded.
    with jax.enable_x64(True):
        params, extras = read_params(params_json_path)
    model = model or extras.get("model", MODEL_NAMES[0])
    warn_filled_for_model(params_json_path, extras, model)
    tap_weights = tap_weights or extras.get("tap_weights")
    if format in ("hdrp", "unreal"):  # issue 34: the engines' assets
        from .engine_profiles import engine_asset

        if get_model(model).layout != "disk":
            raise InvalidInputError(
                f"format: {format} takes a burley fit (model burley), got model {model}; refit with --model burley"
            )
        # Refuses a d the fit did not measure, and takes the depth unit from the file.
        text = to_json(engine_asset(params, extras, format, source=os.fspath(params_json_path), **(engine or {})))
        if out_path is not None:
            write_texts_atomic({out_path: text}, overwrite=overwrite)
        return text
    constants = shader_constants(params, model, tap_weights=tap_weights, taps=taps, strength=strength,
                                 light_terms=extras.get("light_terms"))
    text = to_json(constants) if format == "json" else to_hlsl(constants)
    if out_path is not None:
        files = {os.fspath(out_path): text}
        shaders = shader_files(out_path, model, extras.get("light_terms")) if with_shader else {}
        files.update(shaders)
        write_texts_atomic(files, overwrite=overwrite, roles=dict.fromkeys(shaders, "a shader file"))
    return text
