"""How each engine reads the profile asset invsss writes: a second implementation, from the engines' code.

:mod:`invsss.io.engine_profiles` turns a ``burley`` fit into the fields of an
engine's asset. This module goes the other way, following what the engine does
with those fields, step by step, as its published source does it, and written
independently of the export (its own scaling functions, its own clamps): a test
that exports and reads back then checks the export against the engine, not
against itself (docs/renderer.md, "How an engine reads the asset").

HDRP (Unity's High Definition Render Pipeline, ``DiffusionProfileSettings.cs``)
    ``UpdateKernel`` multiplies ``scatteringDistance`` (a colour) by
    ``scatteringDistanceMultiplier`` and takes the shape parameter
    ``S = min(2^24, 1 / sd)`` per channel; ``DiffusionProfile.hlsl`` evaluates
    ``S (e^{-S r} + e^{-S r / 3}) / (8 pi r)`` with ``r`` in mm, so Burley's
    ``d = 1 / S``. ``Validate`` keeps ``worldScale >= 0.001``, and
    ``SubsurfaceScattering.compute`` turns view-space distances into mm with
    ``1000 worldScale`` (metres per scene unit).
Unreal (``SubsurfaceProfile.cpp``, ``BurleyNormalizedSSS.cpp``, Unreal Engine 5)
    The editor holds ``MeanFreePathDistance`` in [0.1, 50] cm,
    ``MeanFreePathColor`` in [0.001, 1] and ``SurfaceAlbedo`` in [0.01, 1]
    (the properties' ``ClampMin``/``ClampMax``). When the profile texture is
    built (``FSubsurfaceProfileTexture::CreateTexture``) colour and albedo are
    clamped again to [0.009, 1] (its ``Bias``), the diffuse mean free path is
    ``GetDiffuseMeanFreePathFromMeanFreePath(A, colour x distance) x 10 / 0.6``
    mm, that is ``l s_sl(A) / s_perp(A) x 10 / 0.6`` with Christensen & Burley's
    searchlight fit ``s_sl(A) = 3.5 + 100 (A - 0.33)^4`` and perpendicular fit
    ``s_perp(A) = 1.85 - A + 7 |A - 0.8|^3`` (``Dmfp2MfpMagicNumber`` is the
    0.6), clamped to 500 mm (the texture's encoding range), and the shader's
    profile uses ``d = dmfp / s_sl(A)`` (``Burley_ScatteringProfile`` with
    ``S = GetSearchLightDiffuseScalingFactor``). In one line:
    ``d = 10 l / (0.6 s_perp(A))`` mm.

Both readings return Burley's ``d`` per channel in mm, as the engine renders it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..validation import InvalidInputError

__all__ = ["hdrp_reading", "hdrp_mm_per_unit", "hdrp_transmittance", "unreal_reading", "unreal_transmittance",
           "UNREAL_LIMITS"]

#: HDRP's cap on the shape parameter (``UpdateKernel``: "rather inconvenient to support S = Inf").
_HDRP_MAX_SHAPE = 16777216.0
#: HDRP's ``Validate``: the smallest ``worldScale``.
_HDRP_MIN_WORLD_SCALE = 0.001

#: Unreal's clamps on the fields, as (low, high): the editor's ``ClampMin``/``ClampMax``
#: and, for colour and albedo, the texture builder's ``Bias`` floor of 0.009 after them.
UNREAL_LIMITS: dict[str, Any] = {
    "MeanFreePathDistance": (0.1, 50.0),  # cm, editor
    "MeanFreePathColor": (0.001, 1.0),  # editor
    "SurfaceAlbedo": (0.01, 1.0),  # editor
    "WorldUnitScale": (0.1, 50.0),  # editor
    "render_floor": 0.009,  # CreateTexture's Bias on colour and albedo
    "dmfp_max_mm": 500.0,  # DEC_UNIT_TO_DIFFUSEMEANFREEPATH_IN_MM: the encoded range
}
#: ``Dmfp2MfpMagicNumber`` of SubsurfaceProfile.cpp.
_UNREAL_DMFP_TO_MFP = 0.6
_CM_TO_MM = 10.0


def _vector(fields: dict, key: str, size: int = 3) -> np.ndarray:
    try:
        value = np.asarray(fields[key], np.float64).reshape(-1)
    except KeyError:
        raise InvalidInputError(f"fields: missing {key!r}") from None
    except (TypeError, ValueError):
        raise InvalidInputError(f"fields: {key} must be numbers, got {fields[key]!r}") from None
    if value.size < size or not np.all(np.isfinite(value[:size])):
        raise InvalidInputError(f"fields: {key} needs {size} finite numbers, got {fields[key]!r}")
    return value[:size]


def _number(fields: dict, key: str) -> float:
    return float(_vector(fields, key, 1)[0])


def hdrp_reading(fields: dict) -> np.ndarray:
    """Burley's ``d`` per channel (mm) that HDRP renders from Diffusion Profile ``fields``, shape (3,).

    Parameters
    ----------
    fields : dict
        ``scatteringDistance`` (3 or 4 numbers; alpha ignored) and
        ``scatteringDistanceMultiplier``.

    Examples
    --------
    >>> hdrp_reading({"scatteringDistance": [1.0, 0.5, 0.25], "scatteringDistanceMultiplier": 2.0}).tolist()
    [2.0, 1.0, 0.5]
    """
    scattering = _vector(fields, "scatteringDistance") * _number(fields, "scatteringDistanceMultiplier")
    with np.errstate(divide="ignore"):
        shape = np.minimum(_HDRP_MAX_SHAPE, 1.0 / scattering)
    return 1.0 / shape


def hdrp_transmittance(fields: dict, thickness_map) -> np.ndarray:
    """The transmittance per channel HDRP computes for a thin object from Diffusion
    Profile ``fields`` at thickness-map values ``thickness_map`` (in [0, 1]), shape (..., 3).

    As HDRP does it: ``Validate`` clamps ``thicknessRemap`` (``y >= 0``, ``0 <= x <= y``);
    ``UpdateCache`` stores ``(x, y - x)`` and the tint times 0.25; ``FillMaterialTransmission``
    remaps the map's value to mm, ``x + (y - x) m``; ``ComputeTransmittanceDisney`` returns
    ``0.25 tint e (e^2 + 3)`` with ``e = 2^(-log2(e) S t / 3)``, ``S`` the shape parameter
    of :func:`hdrp_reading`. The light it multiplies (the wrapped back cosine, the
    light's colour, the albedo) is the term's own (docs/model.md, section 8).

    Examples
    --------
    >>> f = {"scatteringDistance": [1.0, 1.0, 1.0], "scatteringDistanceMultiplier": 2.0,
    ...      "transmissionTint": [1.0, 0.5, 0.25], "thicknessRemap": [0.0, 5.0]}
    >>> hdrp_transmittance(f, 0.0).tolist()         # no thickness: the tint
    [1.0, 0.5, 0.25]
    """
    remap = _vector(fields, "thicknessRemap", 2)
    high = max(remap[1], 0.0)
    low = min(max(remap[0], 0.0), high)
    start, extent = low, high - low
    quarter_tint = 0.25 * _vector(fields, "transmissionTint")
    shape = 1.0 / hdrp_reading(fields)
    thickness_mm = start + extent * np.asarray(thickness_map, np.float64)[..., None]
    log2_e = 1.0 / np.log(2.0)
    third = np.exp2((log2_e * (-1.0 / 3.0) * thickness_mm) * shape)
    return quarter_tint * (third * (third * third + 3.0))


def hdrp_mm_per_unit(fields: dict) -> float:
    """Millimetres per HDRP scene unit: ``1000 max(worldScale, 0.001)``.

    Examples
    --------
    >>> hdrp_mm_per_unit({"worldScale": 1.0})
    1000.0
    """
    return 1000.0 * max(_number(fields, "worldScale"), _HDRP_MIN_WORLD_SCALE)


def _perpendicular(albedo: np.ndarray) -> np.ndarray:
    # BurleyNormalizedSSS.cpp, GetPerpendicularScalingFactor (with its abs()).
    return 1.85 - albedo + 7.0 * np.abs(albedo - 0.8) ** 3


def _searchlight(albedo: np.ndarray) -> np.ndarray:
    # BurleyNormalizedSSS.cpp, GetSearchLightDiffuseScalingFactor.
    return 3.5 + 100.0 * (albedo - 0.33) ** 4


def unreal_reading(fields: dict) -> np.ndarray:
    """Burley's ``d`` per channel (mm) that Unreal renders from Subsurface Profile ``fields``, shape (3,).

    The editor's clamps come first (a value typed or set outside them is held at
    the limit), then the texture builder's, then the conversion from the mean
    free path to the diffuse mean free path and from that to ``d``.

    Parameters
    ----------
    fields : dict
        ``SurfaceAlbedo``, ``MeanFreePathColor`` (3 or 4 numbers; alpha ignored)
        and ``MeanFreePathDistance`` (cm); ``bEnableBurley`` and
        ``bEnableMeanFreePath`` must not be false (Unreal would then convert the
        values as an older asset's, see :func:`invsss.io.engine_profiles.unreal_profile`).

    Examples
    --------
    >>> f = {"SurfaceAlbedo": [0.8] * 3, "MeanFreePathColor": [1.0, 0.5, 0.25], "MeanFreePathDistance": 0.63}
    >>> unreal_reading(f).round(12).tolist()
    [10.0, 5.0, 2.5]
    """
    for flag in ("bEnableBurley", "bEnableMeanFreePath"):
        if fields.get(flag, True) is False:
            raise InvalidInputError(
                f"fields: {flag} is false, so Unreal would convert the values as an older asset's on load; "
                "this reading covers mean-free-path Burley profiles only"
            )
    low, high = UNREAL_LIMITS["MeanFreePathDistance"]
    distance = float(np.clip(_number(fields, "MeanFreePathDistance"), low, high))
    floor = UNREAL_LIMITS["render_floor"]
    low, high = UNREAL_LIMITS["MeanFreePathColor"]
    colour = np.clip(np.clip(_vector(fields, "MeanFreePathColor"), low, high), floor, 1.0)
    low, high = UNREAL_LIMITS["SurfaceAlbedo"]
    albedo = np.clip(np.clip(_vector(fields, "SurfaceAlbedo"), low, high), floor, 1.0)
    mean_free_path_cm = colour * distance
    dmfp_mm = mean_free_path_cm * _searchlight(albedo) / _perpendicular(albedo) * _CM_TO_MM / _UNREAL_DMFP_TO_MFP
    dmfp_mm = np.clip(dmfp_mm, 0.0, UNREAL_LIMITS["dmfp_max_mm"])
    return dmfp_mm / _searchlight(albedo)


#: ``GetNextSmallerPositiveFloat(0x10000)``: CreateTexture's scale into 16-bit unorm.
_UNORM16_SCALE = float(np.nextafter(np.float32(65536.0), np.float32(0.0)))


def _unorm16(value: np.ndarray) -> np.ndarray:
    # CreateTexture writes (uint16)(value * FloatScale); the sampler reads n / 65535.
    return np.floor(np.clip(value, 0.0, 1.0) * _UNORM16_SCALE) / 65535.0


def unreal_transmittance(fields: dict, thickness_mm) -> np.ndarray:
    """The transmittance per channel Unreal looks up for thickness ``thickness_mm`` (mm,
    the key light's path inside), from Subsurface Profile ``fields``, shape (..., 3).

    The table as Epic's C++ builds it (Unreal Engine 5): ``CreateTexture`` clamps
    ``TransmissionTintColor`` to [0.009, 1] and encodes ``ExtinctionScale`` times 0.01,
    both in 16-bit unorm; ``ComputeTransmissionProfileBurley`` fills 32 entries with
    ``tint 0.25 (e^(-S r / L) + 3 e^(-S r / (3 L)))`` at ``r = (i / 32 x 50 + 0.6) /
    u`` mm, ``u = WorldUnitScale / 0.1``, ``S`` the searchlight scaling factor of the
    albedo and ``L`` the diffuse mean free path (as :func:`unreal_reading` derives it),
    and blacks out the last. Then the lookup, as published transcriptions of Unreal's
    ``TransmissionThickness.ush`` give it: the optical depth ``clamp(ExtinctionScale
    t_w + NormalScale / 2, 0.15, 5) + 0.25`` of the thickness in world units
    ``t_w = t / (10 WorldUnitScale)`` (the blur export's world-to-profile scale),
    read at entry ``depth / 5 x 31`` between its neighbours. Left out: the shadow
    mask's 8-bit encoding of the depth, and the phase function the light is weighted by.

    Examples
    --------
    >>> f = {"SurfaceAlbedo": [0.8] * 3, "MeanFreePathColor": [1.0] * 3, "MeanFreePathDistance": 0.1,
    ...      "WorldUnitScale": 1.0, "TransmissionTintColor": [1.0, 0.5, 0.25], "ExtinctionScale": 3.0,
    ...      "NormalScale": 0.0}
    >>> unreal_transmittance(f, [2.0, 20.0]).round(3).tolist()
    [[0.767, 0.383, 0.192], [0.0, 0.0, 0.0]]
    """
    d_mm = unreal_reading(fields)
    albedo = np.clip(np.clip(_vector(fields, "SurfaceAlbedo"), *UNREAL_LIMITS["SurfaceAlbedo"]),
                     UNREAL_LIMITS["render_floor"], 1.0)
    scaling = _searchlight(albedo)
    dmfp = d_mm * scaling
    tint = np.clip(_vector(fields, "TransmissionTintColor"), UNREAL_LIMITS["render_floor"], 1.0)
    world = float(np.clip(_number(fields, "WorldUnitScale"), *UNREAL_LIMITS["WorldUnitScale"]))
    inverse_unit = 0.1 / world
    entries = np.arange(32, dtype=np.float64)
    radius = (entries / 32.0 * 50.0 + 0.6) * inverse_unit
    x = scaling * radius[:, None] / dmfp
    table = _unorm16(0.25 * (np.exp(-x) + 3.0 * np.exp(-x / 3.0)) * tint)
    table[-1] = 0.0
    extinction = _unorm16(np.array(_number(fields, "ExtinctionScale") * 0.01))[()] * 100.0
    normal = _unorm16(np.array(_number(fields, "NormalScale")))[()]
    world_units = np.asarray(thickness_mm, np.float64) / (10.0 * world)
    depth = np.clip(extinction * world_units + 0.5 * normal, 0.15, 5.0) + 0.25
    position = np.clip(depth / 5.0 * 31.0, 0.0, 31.0)
    below = np.minimum(np.floor(position).astype(int), 30)
    share = (position - below)[..., None]
    return table[below] * (1.0 - share) + table[below + 1] * share
