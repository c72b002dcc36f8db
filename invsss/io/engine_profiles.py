"""A ``burley`` fit as the values of Unity HDRP's Diffusion Profile and Unreal's Subsurface Profile.

Both engines blur with Christensen & Burley's normalized diffusion (docs/model.md,
section 5, "The burley model"); they differ in what their asset stores
(docs/renderer.md, "Engine profiles"):

HDRP (``format="hdrp"``)
    ``scatteringDistance`` (a colour) times ``scatteringDistanceMultiplier`` is
    Burley's ``d`` per channel in millimetres: HDRP's ``DiffusionProfile``
    sets its shape parameter ``S = 1 / (colour * multiplier)`` and evaluates
    ``S / (8 pi) (e^{-S r} + e^{-S r / 3})`` at distances in mm. ``worldScale``
    is the size of one scene unit in metres (HDRP converts view-space positions
    with ``mmPerUnit = 1000 worldScale``).
Unreal (``format="unreal"``)
    ``MeanFreePathColor`` times ``MeanFreePathDistance`` (cm) is the mean free
    path ``l`` per channel; the engine turns it into Burley's shape with the
    albedo ``A`` (``SurfaceAlbedo``) as ``d = 10 l / (0.6 s(A))`` mm, where
    ``s(A) = 1.85 - A + 7 |A - 0.8|^3`` is Christensen & Burley's fit for light
    entering perpendicular to the surface (their section 5; Unreal's
    ``GetPerpendicularScalingFactor``) and 0.6 is Unreal's
    ``Dmfp2MfpMagicNumber`` (``SubsurfaceProfile.cpp``). The editor holds
    ``MeanFreePathDistance`` at 0.1 cm or more: a smaller widest ``l`` is
    written as distance 0.1 with the colour scaled down, as Unreal's own asset
    upgrade does (``UpgradeDiffuseMeanFreePathToMeanFreePath``).
    :mod:`invsss.io.engine_readings` follows the engine's reading step by step.

One photograph pair determines ``L d_c`` (the blur in pixels), hence ``d_c`` in
the depth's unit once ``sss_level`` is known (the camera's focal length in
pixels: fit with ``gauge="sss_level"``). It does not determine the engine
scene's unit (``worldScale``, ``WorldUnitScale``), the surface albedo that
Unreal's conversion needs, the index of refraction, or anything the blur
does not see (transmission, texturing mode, specular lobes); the export names
every such field in ``undetermined`` with the value it assumed, never a
fitted-looking number.
"""

from __future__ import annotations

import numpy as np

from ..validation import InvalidInputError, positive_number
from .asset_values import shape_parameters as _distances
from .asset_values import transmission_term

__all__ = [
    "ENGINE_FORMATS",
    "UNREAL_DEFAULT_ALBEDO",
    "perpendicular_scaling",
    "searchlight_scaling",
    "UNREAL_DMFP_TO_MFP",
    "hdrp_profile",
    "hdrp_distances",
    "unreal_profile",
    "unreal_distances",
    "engine_profile",
    "unmeasured_distances",
    "engine_asset",
    "hdrp_transmission",
    "HDRP_THICKNESS_MAP_MM",
]

#: The engine formats of ``invsss export``.
ENGINE_FORMATS = ("hdrp", "unreal")

#: Unreal's default ``SurfaceAlbedo`` of a new Subsurface Profile (its Python
#: API's ``SubsurfaceProfileStruct`` defaults): what the export assumes when no
#: albedo is given.
UNREAL_DEFAULT_ALBEDO = (0.91058, 0.338275, 0.2718)

_MM_PER_CM = 10.0
#: Burley's d (mm) an export accepts: skin's is 0.05-5 mm (Christensen & Burley's
#: measured skins and invsss's fits), wax and marble reach a few tens.
PLAUSIBLE_D_MM = (0.01, 50.0)


#: Unreal's ``Dmfp2MfpMagicNumber`` (SubsurfaceProfile.cpp): its diffuse mean free
#: path is ``l s_sl(A) / (0.6 s(A))``, so ``d = l / (0.6 s(A))``.
UNREAL_DMFP_TO_MFP = 0.6
#: Unreal's editor range of ``MeanFreePathDistance`` (cm): ClampMin, ClampMax.
_UNREAL_DISTANCE_CM = (0.1, 50.0)
#: The smallest colour and albedo Unreal's profile texture keeps (CreateTexture's Bias).
_UNREAL_FLOOR = 0.009
#: Unreal encodes the diffuse mean free path up to 500 mm.
_UNREAL_DMFP_MAX_MM = 500.0


def perpendicular_scaling(albedo):
    """Christensen & Burley's ``s(A) = 1.85 - A + 7 |A - 0.8|^3``: ``d = l / s`` for mean free path ``l``.

    Their fit for light entering perpendicular to the surface (Unreal's
    ``GetPerpendicularScalingFactor``).

    Examples
    --------
    >>> round(float(perpendicular_scaling(0.8)), 12)
    1.05
    """
    a = np.asarray(albedo, np.float64)
    return 1.85 - a + 7.0 * np.abs(a - 0.8) ** 3


def searchlight_scaling(albedo):
    """Christensen & Burley's ``s(A) = 3.5 + 100 (A - 0.33)^4``: ``d = l_d / s`` for diffuse mean free path ``l_d``.

    Their fit for the searchlight configuration (Unreal's
    ``GetSearchLightDiffuseScalingFactor``).

    Examples
    --------
    >>> round(float(searchlight_scaling(0.33)), 12)
    3.5
    """
    a = np.asarray(albedo, np.float64)
    return 3.5 + 100.0 * (a - 0.33) ** 4


def _colour_and_scale(d: np.ndarray) -> tuple[list, float]:
    # The engines' colour pickers hold [0, 1]: the widest channel is 1 and the scale carries it.
    scale = float(d.max())
    return (d / scale).tolist(), scale


def hdrp_profile(d_mm, world_scale: float = 1.0) -> dict:
    """HDRP Diffusion Profile fields for shape parameters ``d_mm`` (one or per R, G, B).

    Examples
    --------
    >>> p = hdrp_profile([2.0, 1.0, 0.5])
    >>> p["scatteringDistance"], p["scatteringDistanceMultiplier"], p["worldScale"]
    ([1.0, 0.5, 0.25], 2.0, 1.0)
    """
    d = _distances(d_mm, "d_mm")
    colour, multiplier = _colour_and_scale(d)
    return {"scatteringDistance": colour, "scatteringDistanceMultiplier": multiplier,
            "worldScale": positive_number(world_scale, "world_scale")}


#: What a thickness map's 1 stands for (mm) unless told: HDRP's default thickness
#: remap ends at 5 mm (``DiffusionProfile``'s constructor, ``thicknessRemap = (0, 5)``).
HDRP_THICKNESS_MAP_MM = 5.0


def hdrp_transmission(tint, thickness_scale: float, d_mm, thickness_map_mm: float = HDRP_THICKNESS_MAP_MM) -> dict:
    """HDRP's transmission fields for a fitted ``transmission`` term, in its thin-object mode.

    The term's transmittance is ``tau T(k t)`` with ``t`` the buffer's thickness in mm
    (docs/model.md, section 8); HDRP's is ``tint T(S t_h)`` with ``S = 1 / d`` per
    channel and ``t_h = remap.x + (remap.y - remap.x) m`` from the material's thickness
    map ``m`` in [0, 1]. With ``m = t / thickness_map_mm`` the two agree when the tint is
    ``tau`` and the remap is ``(0, k d thickness_map_mm)``; that needs one ``d`` for
    every channel (HDRP's remap is one per profile, the term's ``k`` one number).
    ``"ThinObject"``: HDRP's regular mode takes the thickness from the shadow map
    without the remap, where the transmittance's length is the profile's ``d`` alone.

    Examples
    --------
    >>> f = hdrp_transmission(0.6, 0.25, [2.0, 2.0, 2.0], 5.0)
    >>> f["transmissionTint"], f["thicknessRemap"], f["transmissionMode"]
    ([0.6, 0.6, 0.6], [0.0, 2.5], 'ThinObject')
    """
    tau, k, d = transmission_term(tint, thickness_scale, d_mm, "HDRP's thickness remap")
    t_max = positive_number(thickness_map_mm, "thickness_map_mm")
    return {"transmissionMode": "ThinObject", "transmissionTint": tau.tolist(),
            "thicknessRemap": [0.0, float(k * d[0] * t_max)]}


def hdrp_distances(fields: dict) -> np.ndarray:
    """Burley's ``d`` per channel (mm) from HDRP fields: ``colour * multiplier``, shape (3,).

    Examples
    --------
    >>> hdrp_distances(hdrp_profile([2.0, 1.0, 0.5])).tolist()
    [2.0, 1.0, 0.5]
    """
    colour = np.asarray(fields["scatteringDistance"], np.float64)[:3]
    return colour * positive_number(fields["scatteringDistanceMultiplier"], "scatteringDistanceMultiplier")


def unreal_profile(d_mm, albedo=UNREAL_DEFAULT_ALBEDO, world_unit_scale: float = 0.1) -> dict:
    """Unreal Subsurface Profile fields (Burley, mean free path) for shape parameters ``d_mm``.

    ``l_c = 0.6 d_c s(A_c) / 10`` cm (:func:`perpendicular_scaling`,
    :data:`UNREAL_DMFP_TO_MFP`); the widest ``l`` is ``MeanFreePathDistance`` and
    the colour ``l_c / max(l)``, except that a widest ``l`` under the editor's
    0.1 cm is written as 0.1 with the colour scaled by ``max(l) / 0.1``. A
    profile Unreal would clamp (a channel under 0.009 of the distance, a
    distance over 50 cm, a diffuse mean free path over 500 mm) is refused.

    ``Implementation`` (Unreal 5.6 and later) selects the Burley sampling
    (``SIH_AFIS``); ``bEnableBurley`` and ``bEnableMeanFreePath`` are hidden in
    Unreal 5's editor but must be true, or loading the asset converts its
    values as an older profile's.

    Examples
    --------
    >>> p = unreal_profile([10.0, 5.0, 2.5], albedo=0.8)
    >>> [round(x, 6) for x in p["MeanFreePathColor"]], round(p["MeanFreePathDistance"], 6)
    ([1.0, 0.5, 0.25], 0.63)
    >>> p = unreal_profile([1.0, 0.5, 0.25], albedo=0.8)
    >>> [round(x, 6) for x in p["MeanFreePathColor"]], p["MeanFreePathDistance"]
    ([0.63, 0.315, 0.1575], 0.1)
    """
    d = _distances(d_mm, "d_mm")
    try:
        a = np.asarray(albedo, np.float64).reshape(-1)
    except (TypeError, ValueError):
        a = np.array([np.nan])
    if a.size not in (1, 3) or not np.all((a >= 0.01) & (a <= 1.0)):
        raise InvalidInputError(
            f"albedo: expected one or three values in [0.01, 1] (Unreal's range), got {albedo!r}"
        )
    a = np.broadcast_to(a, (3,)).copy()
    mfp_cm = UNREAL_DMFP_TO_MFP * d * perpendicular_scaling(a) / _MM_PER_CM
    colour, distance = _colour_and_scale(mfp_cm)
    low, high = _UNREAL_DISTANCE_CM
    if distance < low:
        # Unreal's own upgrade of small profiles: the distance at its floor, the colour scaled down.
        colour = (np.asarray(colour) * distance / low).tolist()
        distance = low
    if distance > high:
        raise InvalidInputError(
            f"d_mm: the widest mean free path {distance:g} cm is over Unreal's {high:g} cm "
            f"(d = {d.max():g} mm); is the fit's depth in mm?"
        )
    if min(colour) < _UNREAL_FLOOR:
        raise InvalidInputError(
            f"d_mm: a channel's mean free path is {min(colour):.3g} of MeanFreePathDistance, under the "
            f"{_UNREAL_FLOOR} Unreal keeps (it would render wider); d = {d.tolist()} mm"
        )
    if np.any(d * searchlight_scaling(a) > _UNREAL_DMFP_MAX_MM):
        raise InvalidInputError(
            f"d_mm: {d.tolist()} mm is over the {_UNREAL_DMFP_MAX_MM:g} mm diffuse mean free path Unreal encodes"
        )
    return {"SurfaceAlbedo": a.tolist(), "MeanFreePathColor": colour, "MeanFreePathDistance": distance,
            "WorldUnitScale": positive_number(world_unit_scale, "world_unit_scale"),
            "Implementation": "SIH_AFIS", "bEnableBurley": True, "bEnableMeanFreePath": True}


def unreal_distances(fields: dict) -> np.ndarray:
    """Burley's ``d`` per channel (mm) from Unreal fields: ``10 colour distance / (0.6 s(A))``, shape (3,).

    The inverse of :func:`unreal_profile` within the engine's ranges; for what
    Unreal does outside them, :func:`invsss.io.engine_readings.unreal_reading`.

    Examples
    --------
    >>> unreal_distances(unreal_profile([1.0, 0.5, 0.25], albedo=0.8)).round(12).tolist()
    [1.0, 0.5, 0.25]
    """
    colour = np.asarray(fields["MeanFreePathColor"], np.float64)[:3]
    mfp_mm = colour * positive_number(fields["MeanFreePathDistance"], "MeanFreePathDistance") * _MM_PER_CM
    albedo = np.asarray(fields["SurfaceAlbedo"], np.float64)[:3]
    return mfp_mm / (UNREAL_DMFP_TO_MFP * perpendicular_scaling(albedo))


def unmeasured_distances(extras: dict) -> dict[str, str]:
    """Which of a fit's shape parameters were not measured, and why, from its params file's report.

    A ``burley`` fit's ``variances`` are Burley's ``d_c^2``. They are not a
    measurement when the fit held them (``fixed``: given with ``--fix`` or held
    at the start by ``gauge="variances"``), when the data left them
    undetermined (``undetermined``; ``read_params`` then fills them from the
    estimate), or when the inputs could not determine them (``inputs.held``).
    A params file without a fit report (written by hand) claims nothing and
    gives an empty dict.

    Examples
    --------
    >>> unmeasured_distances({"fixed": {"variances": [0.576] * 3}, "gauge": "variances"})
    {'variances': 'held at 0.759, 0.759, 0.759 mm by the fit (gauge variances), not measured'}
    >>> unmeasured_distances({"undetermined": ["variances[1]"], "gauge": "depth"})
    {'variances[1]': 'not determined by the fit (no standard error)'}
    """
    out = {}
    fixed = extras.get("fixed") or {}
    if "variances" in fixed:
        d = ", ".join(f"{x:.3g}" for x in np.sqrt(np.asarray(fixed["variances"], np.float64)).reshape(-1))
        how = f"gauge {extras['gauge']}" if extras.get("gauge") == "variances" else "--fix"
        out["variances"] = f"held at {d} mm by the fit ({how}), not measured"
    for entry in extras.get("undetermined") or ():
        if isinstance(entry, str) and entry.startswith("variances"):
            out[entry] = "not determined by the fit (no standard error)"
    inputs = extras.get("inputs")
    # inputs.held maps each held parameter's name to its value and reason.
    for name in (inputs.get("held") or {}) if isinstance(inputs, dict) else ():
        if name.startswith("variances") and name not in out:
            out[name] = "held because the inputs cannot determine it"
    return out


def engine_profile(params, format: str, *, mm_per_unit: float = 1.0, albedo=None, world_scale=None,
                   assumed: dict | None = None, transmission: dict | None = None,
                   thickness_map_mm: float | None = None, thickness_range_mm=None) -> dict:
    """The asset values of engine ``format`` for a ``burley`` fit's parameters.

    Parameters
    ----------
    params : SSSParams
        A ``burley`` fit: ``variances`` are ``d_c^2`` in the depth's unit squared.
    format : {"hdrp", "unreal"}
    mm_per_unit : float
        Millimetres per unit of the pair's depth (1 for depth in mm, as recommended).
    albedo : float or 3 floats, optional
        ``unreal``: the surface albedo for the mean-free-path conversion; default
        :data:`UNREAL_DEFAULT_ALBEDO` (then listed as undetermined).
    world_scale : float, optional
        The engine scene's unit: HDRP ``worldScale`` (metres per unit, default 1)
        or Unreal ``WorldUnitScale`` (default 0.1); listed as undetermined when not given.
    assumed : dict, optional
        Shape parameters that were not measured (:func:`unmeasured_distances`),
        written anyway at the user's request: each is listed under ``assumed``
        in the output, and the distance fields under ``undetermined``.
    transmission : dict, optional
        A fitted ``transmission`` term, ``{"transmission": tint, "thickness_scale": k}``
        (params.json's ``light_terms``): both formats write their fields
        (:func:`hdrp_transmission`, :func:`invsss.io.unreal_transmission.unreal_transmission`).
    thickness_map_mm : float, optional
        ``hdrp`` with ``transmission``: the thickness in mm that the material's
        thickness map's 1 stands for (default :data:`HDRP_THICKNESS_MAP_MM`, then
        listed as undetermined).
    thickness_range_mm : (float, float), optional
        ``unreal`` with ``transmission``: the thicknesses (mm) its tint is matched
        over (default :data:`~invsss.io.unreal_transmission.UNREAL_TRANSMISSION_RANGE_MM`,
        then listed as undetermined).

    Returns
    -------
    dict
        ``format``, ``fields`` (the asset's values), ``shapeParameterMm`` (``d`` per
        channel), ``undetermined`` (field: why, and what was assumed) and ``units``;
        ``unreal`` with ``transmission`` adds ``transmissionMatch`` (how much of the
        fitted transmitted light Unreal renders over the thickness range).

    Examples
    --------
    >>> import invsss
    >>> p = invsss.SSSParams(900.0, 0.0, 1.0, [1.0, 1.0, 1.0], [4.0, 1.0, 0.25])
    >>> out = engine_profile(p, "hdrp")
    >>> out["fields"]["scatteringDistanceMultiplier"], sorted(out["undetermined"])[:2]
    (2.0, ['indexOfRefraction', 'texturingMode'])
    """
    if format not in ENGINE_FORMATS:
        raise InvalidInputError(f"format: expected one of {', '.join(ENGINE_FORMATS)}, got {format!r}")
    scale = positive_number(mm_per_unit, "mm_per_unit")
    d = np.sqrt(np.asarray(params.variances, np.float64)) * scale
    if d.size not in (1, 3):
        raise InvalidInputError(
            f"params: a burley fit has one or three shape parameters (variances = d^2), got {d.size}"
        )
    low, high = PLAUSIBLE_D_MM
    if d.min() < low or d.max() > high:
        # A fit on depth in metres gives d 1000 times too small, in cm 10 times, with no other sign.
        raise InvalidInputError(
            f"params: Burley's d of {', '.join(f'{x:.3g}' for x in d.reshape(-1))} mm (at {scale:g} mm per "
            f"depth unit) is outside {low:g}-{high:g} mm, where skin and other translucent materials lie; "
            "was the fit's depth in another unit? Refit with --depth-unit, or give --mm-per-unit"
        )
    undetermined, match = {}, None
    if assumed:
        reasons = "; ".join(f"{k}: {v}" for k, v in assumed.items())
        distance_fields = ("scatteringDistance, scatteringDistanceMultiplier" if format == "hdrp"
                           else "MeanFreePathColor, MeanFreePathDistance")
        undetermined[distance_fields] = f"ASSUMED, not measured ({reasons})"
    if format == "hdrp":
        if world_scale is None:
            undetermined["worldScale"] = "the engine scene's unit; assumed HDRP's default 1 (1 unit = 1 m)"
        fields = hdrp_profile(d, 1.0 if world_scale is None else world_scale)
        undetermined["indexOfRefraction"] = "the blur does not see the specular reflection; HDRP's default is 1.4"
        undetermined["texturingMode"] = "whether albedo is applied before or after the blur is the material's choice"
        units = "scatteringDistance x scatteringDistanceMultiplier = Burley's d per channel in mm"
        if transmission is None:
            undetermined["transmissionTint"] = "transmission is not in a front-lit photograph pair"
        else:
            if thickness_map_mm is None:
                undetermined["thicknessRemap"] = (
                    f"the material's thickness map convention: its 1 assumed to stand for {HDRP_THICKNESS_MAP_MM:g} mm "
                    "(HDRP's default remap); the remap scales with it"
                )
            fields.update(hdrp_transmission(transmission["transmission"], transmission["thickness_scale"], d,
                                            HDRP_THICKNESS_MAP_MM if thickness_map_mm is None else thickness_map_mm))
            units += ("; thicknessRemap in mm for a thickness map of the fit's thickness (mm) over "
                      f"{HDRP_THICKNESS_MAP_MM if thickness_map_mm is None else thickness_map_mm:g} mm")
    else:
        if albedo is None:
            undetermined["SurfaceAlbedo"] = (
                "not determined by a photograph pair (the fit's gain absorbs it); the mean free path assumes "
                f"Unreal's default {list(UNREAL_DEFAULT_ALBEDO)}"
            )
        if world_scale is None:
            undetermined["WorldUnitScale"] = "the engine scene's unit; assumed Unreal's default 0.1"
        fields = unreal_profile(d, UNREAL_DEFAULT_ALBEDO if albedo is None else albedo,
                                0.1 if world_scale is None else world_scale)
        undetermined["IOR"] = "the blur does not see the specular reflection"
        if transmission is None:
            undetermined["Tint, BoundaryColorBleed, TransmissionTintColor"] = "not in a front-lit photograph pair"
        else:
            undetermined["Tint, BoundaryColorBleed"] = "not in a front-lit photograph pair"
            extra, match = _unreal_transmission_fields(transmission, d, fields["WorldUnitScale"],
                                                       thickness_range_mm, undetermined)
            fields.update(extra)
        units = ("MeanFreePathColor x MeanFreePathDistance = mean free path l per channel in cm; "
                 "Burley's d = 10 l / (0.6 (1.85 - A + 7 |A - 0.8|^3)) mm (Unreal 5; Implementation: Unreal 5.6+)")
    out = {"format": format, "fields": fields, "shapeParameterMm": d.reshape(-1).tolist(),
           "undetermined": undetermined, "units": units}
    if match is not None:
        out["transmissionMatch"] = match
    if assumed:
        out["assumed"] = dict(assumed)
    return out


def _unreal_transmission_fields(transmission: dict, d, world_unit_scale: float, thickness_range_mm,
                                undetermined: dict) -> tuple[dict, dict]:
    # Unreal's transmission fields, with what its reading leaves unsure named in ``undetermined``.
    from .unreal_transmission import UNREAL_TRANSMISSION_RANGE_MM, unreal_transmission

    if thickness_range_mm is None:
        thickness_range_mm = UNREAL_TRANSMISSION_RANGE_MM
        undetermined["TransmissionTintColor"] = (
            "matched over thicknesses of {:g}-{:g} mm (assumed; give --thickness-range-mm)".format(
                *UNREAL_TRANSMISSION_RANGE_MM))
    fields, match = unreal_transmission(transmission["transmission"], transmission["thickness_scale"], d,
                                        world_unit_scale, thickness_range_mm)
    undetermined["ExtinctionScale"] = (
        "computed for a shadow-map thickness in world units of 10 WorldUnitScale mm, with the optical depth's "
        "floor and bias as published transcriptions of Unreal's shader give them; not checked in a running editor")
    undetermined["NormalScale, ScatteringDistribution"] = (
        "the fitted term has no normal offset nor phase function: Unreal's default normal scale, an isotropic phase")
    low = min(lo for lo, _ in match["renderedOverFitted"])
    if low < 0.9:
        undetermined["TransmissionTintColor"] = (
            f"Unreal renders {low:.2f} of the fitted transmitted light at some thickness in "
            f"{match['thicknessMm'][0]:g}-{match['thicknessMm'][1]:g} mm: its table starts "
            f"{match['tableStartMm']:.3g} profile mm in and the tint stops at 1 "
            "(docs/renderer.md, 'Transmission in Unreal')")
    return fields, match


def engine_asset(params, extras: dict, format: str, *, source: str = "params", mm_per_unit=None,
                 albedo=None, world_scale=None, accept_assumed: bool = False, thickness_map_mm=None,
                 thickness_range_mm=None) -> dict:
    """:func:`engine_profile` for a params file's content, refusing what the fit did not measure.

    Parameters
    ----------
    params : SSSParams
        A ``burley`` fit's parameters.
    extras : dict
        The rest of its params file (``read_params``): the fit's report and ``depth_unit``.
    format : {"hdrp", "unreal"}
    source : str
        What the messages call the file.
    mm_per_unit : float, optional
        Millimetres per unit of the fit's depth; default from ``depth_unit`` (mm
        when absent). A value that disagrees with a recorded unit is refused.
    albedo, world_scale
        As in :func:`engine_profile`.
    accept_assumed : bool
        Write shape parameters the fit held or left undetermined
        (:func:`unmeasured_distances`), marked as assumed; otherwise they are refused.
    thickness_map_mm, thickness_range_mm : optional
        As in :func:`engine_profile`, for a fit with the ``transmission`` term.

    Examples
    --------
    >>> import invsss
    >>> p = invsss.SSSParams(900.0, 0.0, 1.0, [1.0, 1.0, 1.0], [1.0, 0.25, 0.0625])
    >>> engine_asset(p, {"depth_unit": "cm"}, "hdrp")["shapeParameterMm"]
    [10.0, 5.0, 2.5]
    >>> engine_asset(p, {"fixed": {"variances": [1.0, 0.25, 0.0625]}, "gauge": "variances"}, "hdrp")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: params: Burley's d (variances) was held at 1, 0.5, 0.25 mm by the fit (gauge variances), not measured; refit with --model burley and no --gauge (its default measures d), or give --accept-assumed to write it marked as assumed
    """  # noqa: E501
    from ..forward.params import DEPTH_UNITS

    recorded = extras.get("depth_unit")
    if mm_per_unit is None:
        mm_per_unit = DEPTH_UNITS[recorded or "mm"]
    elif recorded is not None and positive_number(mm_per_unit, "mm_per_unit") != DEPTH_UNITS[recorded]:
        raise InvalidInputError(
            f"mm_per_unit: {mm_per_unit!r} disagrees with {source}, which records depth_unit {recorded} "
            f"({DEPTH_UNITS[recorded]:g} mm per unit); leave it out to use the recorded unit"
        )
    # Nothing unmeasured leaves as if measured: an engine asset has no place to say
    # that a distance was the fit's start.
    unmeasured = unmeasured_distances(extras)
    if unmeasured and not accept_assumed:
        entry, why = next(iter(unmeasured.items()))
        raise InvalidInputError(
            f"{source}: Burley's d ({entry}) was {why}; refit with --model burley and no --gauge (its default "
            "measures d), or give --accept-assumed to write it marked as assumed",
            field=source,
        )
    terms = extras.get("light_terms") or {}
    tint = np.asarray(terms.get("transmission", 0.0), np.float64)
    transmission = ({"transmission": tint, "thickness_scale": terms["thickness_scale"]}
                    if np.any(tint > 0.0) and "thickness_scale" in terms else None)
    return engine_profile(params, format, mm_per_unit=mm_per_unit, albedo=albedo, world_scale=world_scale,
                          assumed=unmeasured or None, transmission=transmission, thickness_map_mm=thickness_map_mm,
                          thickness_range_mm=thickness_range_mm)
