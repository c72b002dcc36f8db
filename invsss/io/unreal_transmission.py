"""A fitted ``transmission`` term as the transmission fields of Unreal's Subsurface Profile.

The term's transmittance is ``tau T(k t)`` with ``t`` the thickness (mm) towards
the key light and ``T(x) = (e^-x + 3 e^(-x/3)) / 4`` (docs/model.md, section 8).
Unreal bakes its own from the profile: ``ComputeTransmissionProfileBurley``
(``BurleyNormalizedSSS.cpp``, Unreal Engine 5) tabulates ``TransmissionTintColor
x T((r + r0) / d)`` at 32 distances ``r_i = i / 32 x 50 mm / u`` with the offset
``r0 = 0.6 mm / u`` (its ``ProfileRadiusOffset`` of 0.06 cm) and
``u = WorldUnitScale / 0.1``, blacks out the last entry, and the shader looks
the table up with an optical depth ``o = clamp(ExtinctionScale t_w + NormalScale / 2,
0.15, 5) + 0.25`` (``t_w`` the shadow map's thickness in world units), entry
``o / 5 x 31``. So the engine's transmittance is the term's with

* the slope ``k`` when ``ExtinctionScale = k d u^2 / 9.6875`` (with the world
  unit ``t_w = t / (10 WorldUnitScale)``, the world-to-profile scale the blur's
  export uses, docs/renderer.md; 9.6875 mm = 50 mm x 31 / 32 / 5 is the profile
  distance per unit of optical depth), and one ``d`` for every channel (``ExtinctionScale``
  is one number, as the term's ``k`` is);
* an offset: the table is read from ``0.4 x 9.6875 + 0.6 = 4.5`` profile mm over
  ``u`` (the floor and the 0.25 above, and ``r0``), which the tint makes up for
  where it can, and an end: past the optical depth 150 / 31 the table fades to
  its black last entry, about ``48 / u`` profile mm. The tint is held to [0.009, 1] (``CreateTexture``'s clamp), so a
  profile whose ``d`` is small beside that start renders less light than the fit
  measured; :func:`unreal_transmission` says how much.

The shader's part (the optical depth's floor, bias and normal offset, the
index) is read from two published transcriptions of Unreal's
``TransmissionThickness.ush``/``TransmissionCommon.ush``, not from Epic's shader
itself, and the thickness's world unit was not checked in a running editor:
the export lists ``ExtinctionScale`` as computed under that reading.
:func:`invsss.io.engine_readings.unreal_transmittance` follows the same chain
from the fields, with the table as Epic's C++ builds it.
"""

from __future__ import annotations

import numpy as np

from ..validation import InvalidInputError
from .asset_values import transmission_term

__all__ = ["unreal_transmission", "UNREAL_TRANSMISSION_RANGE_MM", "UNREAL_NORMAL_SCALE"]

#: The thickness range (mm) over which the tint is matched unless told: where
#: the key light crosses an ear or a nose's wing.
UNREAL_TRANSMISSION_RANGE_MM = (1.0, 10.0)
#: Unreal's default ``NormalScale`` (``FSubsurfaceProfileStruct``); the term has no
#: counterpart, so the export keeps the default and the tint absorbs its offset.
UNREAL_NORMAL_SCALE = 0.08

_DEPTH_FLOOR, _DEPTH_BIAS, _DEPTH_MAX = 0.15, 0.25, 5.0
_TABLE_SIZE = 32
_TABLE_MM = 50.0  # MaxTransmissionProfileDistance (5 cm) in mm
_OFFSET_MM = 0.6  # ProfileRadiusOffset (0.06 cm) in mm
_TINT_RANGE = (0.009, 1.0)
#: ExtinctionScale's resolution: CreateTexture encodes it times 0.01 in 16-bit unorm.
_EXTINCTION_STEP = 100.0 / 65535.0


def _transmittance(x: np.ndarray) -> np.ndarray:
    third = np.exp(-x / 3.0)
    return 0.25 * third * (third * third + 3.0)


def _optical_depth(thickness_mm, extinction_scale: float, world_unit_scale: float) -> np.ndarray:
    world_units = np.asarray(thickness_mm, np.float64) / (10.0 * world_unit_scale)
    return np.clip(extinction_scale * world_units + UNREAL_NORMAL_SCALE / 2.0, _DEPTH_FLOOR, _DEPTH_MAX) + _DEPTH_BIAS


def _engine_shape(thickness_mm, extinction_scale: float, d: float, world_unit_scale: float) -> np.ndarray:
    """Unreal's transmittance over its tint, ``T((r + r0) / d)`` as its 32-entry table
    holds it (the last entry black), read between entries at ``depth / 5 x 31``."""
    unit = world_unit_scale / 0.1
    entries = np.arange(_TABLE_SIZE)
    table = _transmittance((entries / _TABLE_SIZE * _TABLE_MM + _OFFSET_MM) / unit / d)
    table[-1] = 0.0
    depth = _optical_depth(thickness_mm, extinction_scale, world_unit_scale)
    return np.interp(depth / _DEPTH_MAX * (_TABLE_SIZE - 1), entries, table)


def unreal_transmission(tint, thickness_scale: float, d_mm, world_unit_scale: float = 0.1,
                        thickness_range_mm=UNREAL_TRANSMISSION_RANGE_MM) -> tuple[dict, dict]:
    """Unreal's transmission fields for a fitted ``transmission`` term, and how closely they render it.

    ``ExtinctionScale`` gives the term's slope ``k`` (to the 16-bit step Unreal's
    profile texture keeps it in, 100 / 65535); the tint per channel is the
    least-squares match, in relative terms, of ``tint T((r(t) + r0) / d)`` to
    ``tau T(k t)`` over ``thickness_range_mm``, held to Unreal's [0.009, 1].

    Parameters
    ----------
    tint : float or 3 floats
        The fitted tint ``tau`` (>= 0).
    thickness_scale : float
        The fitted ``k`` (1/mm).
    d_mm : float or 3 floats
        Burley's ``d`` (mm) the exported profile renders; one value for every channel.
    world_unit_scale : float
        The profile's ``WorldUnitScale``.
    thickness_range_mm : (float, float)
        The thicknesses (mm) the match is made over.

    Returns
    -------
    fields : dict
        ``TransmissionTintColor``, ``ExtinctionScale``, ``NormalScale``, ``ScatteringDistribution``.
    match : dict
        ``thicknessMm`` (the range), ``tableStartMm`` (the profile distance of
        Unreal's thinnest thickness, mm) and ``renderedOverFitted``: per channel, the
        smallest and largest ratio of Unreal's transmittance to the term's over it.

    Examples
    --------
    >>> fields, match = unreal_transmission(0.05, 0.3, 2.0, world_unit_scale=1.0, thickness_range_mm=(1, 7))
    >>> round(fields["ExtinctionScale"], 3), [round(x, 3) for x in fields["TransmissionTintColor"]]
    (6.194, [0.054, 0.054, 0.054])
    >>> [round(x, 2) for x in match["renderedOverFitted"][0]]
    [0.99, 1.01]
    """
    tau, k, d = transmission_term(tint, thickness_scale, d_mm, "Unreal's ExtinctionScale")
    low, high = (float(x) for x in thickness_range_mm)
    if not 0.0 < low < high:
        raise InvalidInputError(f"thickness_range_mm: expected 0 < low < high (mm), got {thickness_range_mm!r}")
    unit = world_unit_scale / 0.1
    # The slope of (r + r0) / d in t is ExtinctionScale 9.6875 / (u^2 d): k when
    # ExtinctionScale = k d u^2 / 9.6875 (module docstring).
    extinction = k * d[0] * unit**2 / (_TABLE_MM / _DEPTH_MAX * (_TABLE_SIZE - 1) / _TABLE_SIZE)
    # The profile texture keeps ExtinctionScale / 100 in 16 bits: write a value it holds
    # exactly, and match the tint to that one.
    extinction = max(round(extinction / _EXTINCTION_STEP), 1) * _EXTINCTION_STEP
    t = np.linspace(low, high, 256)
    engine = _engine_shape(t, extinction, d[0], world_unit_scale)[:, None]
    fitted = tau * _transmittance(k * t)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(fitted > 0.0, engine / fitted, 0.0)
    best = np.where(np.sum(g * g, axis=0) > 0.0, np.sum(g, axis=0) / np.sum(g * g, axis=0), _TINT_RANGE[0])
    tint_out = np.clip(best, *_TINT_RANGE)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(fitted > 0.0, tint_out * engine / fitted, np.inf)
    fields = {"TransmissionTintColor": tint_out.tolist(), "ExtinctionScale": float(extinction),
              "NormalScale": UNREAL_NORMAL_SCALE, "ScatteringDistribution": 0.0}
    # The profile distance of the thinnest optical depth, between entries as the shader reads it.
    first = _optical_depth(0.0, 0.0, world_unit_scale) / _DEPTH_MAX * (_TABLE_SIZE - 1)
    start = float((first / _TABLE_SIZE * _TABLE_MM + _OFFSET_MM) / (world_unit_scale / 0.1))
    match = {"thicknessMm": [low, high], "tableStartMm": start,
             "renderedOverFitted": [[float(ratio[:, c].min()), float(ratio[:, c].max())] for c in range(3)]}
    return fields, match
