"""The light-aware terms' shader constants (docs/model.md, section 8).

One rule for which constants a fit's terms give, shared by the constants file
(:func:`invsss.io.export.shader_constants`) and the shader files that go with it
(:func:`invsss.io.shader_export.shader_files`).
"""

from __future__ import annotations

import numpy as np

from ..forward.light_terms import AFTER_BLUR, LIGHT_TERM_FIELDS, LightTerms
from ..validation import InvalidInputError, did_you_mean

__all__ = ["LIGHT_TERMS_RECORD_KEYS", "light_constants"]


def light_constants(light_terms) -> dict:
    """The shader constants of the light-aware terms in use.

    ``lightShift``, ``grazingGain`` and ``incidenceGain`` (all three when any
    term after the blur is in use, or no law), ``lawAlbedo`` (red, green,
    blue), ``lawStrength`` and ``lawFillStrength`` with the law,
    ``transmissionTint`` (red, green, blue) and ``thicknessScale`` with the transmission.

    Parameters
    ----------
    light_terms : LightTerms or mapping
        The terms, or a fit's ``light_terms`` record (params.json).

    Examples
    --------
    >>> light_constants({"shift": 0.4})
    {'lightShift': 0.4, 'grazingGain': 0.0, 'incidenceGain': 0.0}
    >>> light_constants({"law": 0.9, "law_strength": 0.5})["lawAlbedo"]
    [0.9, 0.9, 0.9]
    """
    if isinstance(light_terms, LightTerms):
        given = {term: getattr(light_terms, term) for term in light_terms.used}
        if "law" in given or "fill" in given:
            given["law"], given["law_strength"] = light_terms.law, light_terms.law_strength
        after = [getattr(light_terms, term) for term in AFTER_BLUR]
    elif hasattr(light_terms, "get"):
        _check_keys(light_terms)
        given = {term: light_terms[term] for term in (*AFTER_BLUR, "law", "law_strength", "fill")
                 if term in light_terms}
        after = [light_terms.get(term, 0.0) for term in AFTER_BLUR]
    else:
        raise InvalidInputError(
            f"light_terms: expected an invsss.LightTerms or a mapping, got {type(light_terms).__name__}",
            field="light_terms",
        )
    tint = np.asarray(light_terms.transmission if isinstance(light_terms, LightTerms)
                      else light_terms.get("transmission", 0.0), np.float64)
    scale = float(np.asarray(light_terms.thickness_scale if isinstance(light_terms, LightTerms)
                             else light_terms.get("thickness_scale", 1.0), np.float64))
    # Checked as LightTerms, written from the given numbers: LightTerms holds
    # JAX's default float32 outside x64, which would round them.
    shift, grazing, incidence = (float(np.asarray(v, np.float64)) for v in after)
    law = None if given.get("law") is None else np.asarray(given["law"], np.float64)
    # A params file from before the strength existed applied the law in full.
    strength = float(np.asarray(given.get("law_strength", 1.0), np.float64))
    fill = float(np.asarray(given.get("fill", 0.0), np.float64))
    LightTerms(shift, grazing, incidence, law, strength, fill).check()  # type: ignore[arg-type]  # the fields' converters take array-likes
    out: dict = {}
    if law is None or any(term in given for term in AFTER_BLUR):
        out.update(lightShift=shift, grazingGain=grazing, incidenceGain=incidence)
    if law is not None:
        if law.size not in (1, 3):
            raise InvalidInputError(f"light_terms.law: expected one albedo or three (RGB), got {law.size}")
        out["lawAlbedo"] = np.broadcast_to(law.ravel(), (3,)).tolist()
        out["lawStrength"] = strength
        if fill != 0.0:
            out["lawFillStrength"] = fill
    if np.any(tint != 0.0):
        LightTerms(transmission=tint, thickness_scale=scale).check()  # type: ignore[arg-type]  # the fields' converters take array-likes
        if tint.size not in (1, 3):
            raise InvalidInputError(f"light_terms.transmission: expected one tint or three (RGB), got {tint.size}",
                                    field="light_terms.transmission")
        out["transmissionTint"] = np.broadcast_to(tint.ravel(), (3,)).tolist()
        out["thicknessScale"] = scale
    return out


#: What else a fit's ``light_terms`` record holds (params.json; docs/params-json.md):
#: a mapping with these is accepted as the terms it reports.
LIGHT_TERMS_RECORD_KEYS = ("stderr", "fixed", "psnr_plain", "psnr_without", "fallback")


def _check_keys(light_terms) -> None:
    """Refuse a key that is neither a term nor part of a fit's record: a misspelt
    term would otherwise be left out, and its constant exported switched off."""
    known = (*LIGHT_TERM_FIELDS, *LIGHT_TERMS_RECORD_KEYS)
    for key in light_terms:
        if key not in known:
            raise InvalidInputError(
                f"light_terms: unknown key {key!r}{did_you_mean(key, known)}; expected terms among "
                f"{', '.join(LIGHT_TERM_FIELDS)}",
                field="light_terms",
            )
