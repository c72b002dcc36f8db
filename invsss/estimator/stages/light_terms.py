"""Stage: the light-aware terms, fitted as an extension of the plain model (docs/model.md, section 8)."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ...forward.light_terms import AFTER_BLUR, law_excess
from ..core import Fit, FitCall, Start, estimate_of, psnr_on_mask
from ..options import FitOptions
from ..parametrisation import LIGHT_UNKNOWNS
from ..problem import evaluate, median_thickness_behind
from ..result import FitResult

__all__ = ["against_plain", "plain_model", "scans_for_terms", "term_bounds", "thickness_unused", "unlike_any_medium",
           "with_light_terms"]


#: Every light term's unknown at its identity (docs/model.md, section 8): no
#: shift, no gain, the law at strength 0 on every light (its albedo then does nothing),
#: no transmitted light (its thickness scale then does nothing).
IDENTITY = {"light_shift": 0.0, "grazing": 0.0, "incidence": 0.0, "law_strength": 0.0, "fill_strength": 0.0,
            "transmission": 0.0}
#: A term set that scores this much (dB) below the plain fit on the fit's own
#: mask is not kept: the plain fit is returned, with every term at its identity.
WORSE_THAN_PLAIN_DB = 0.0
#: A term that adds less than this (dB) to the fit's PSNR, measured by setting it
#: to its identity in the final fit, is reported as not describing the pair.
NEGLIGIBLE_DB = 0.05


def with_light_terms(inner: Fit) -> Fit:
    """The stage that fits the light terms (``light_terms``) as an extension of the plain model.

    The terms nest the plain model (each has a value that is the identity): the
    plain model is fitted first, and its estimate, every term at its identity, is
    the start the fit with the terms keeps among its best, so that its loss ends at
    or below the plain fit's. :func:`against_plain` then measures what each term
    added and falls back to the plain fit when the terms scored below it. A call
    with its own ``start`` (an alignment round after the first) skips the plain fit.
    """

    def fit(call: FitCall) -> FitResult:
        options = call.options
        if not options.light_terms or (call.start is not None and not call.start.with_scan):
            return inner(call)
        plain = inner(dataclasses.replace(call, options=plain_model(options)))
        if plain.interrupted:
            return plain

        def compared(solved, **given):
            # The report it was given (the warp's sensitivity, say), then the comparison.
            return against_plain(solved.problem, solved.path, call.report(solved, **given), plain)

        scan = scans_for_terms(options)
        start = Start({**estimate_of(plain), **IDENTITY}, with_scan=scan, scan_after=not scan)
        return inner(dataclasses.replace(call, start=start, report=compared))

    return fit


def scans_for_terms(options: FitOptions) -> bool:
    """Whether the fit with the terms starts from the start scan's points too
    (``term_starts``), or from the plain fit's estimate and the blur scales the
    loss shows to be better (docs/model.md, section 8, "Where a term fit starts").

    ``auto`` scans for ``transmission`` alone: on the tuning ear the plain fit's
    estimate ended 1.1 dB below the scan with it, and a scan around the end
    found no better point. With ``shift,law`` it ended within 0.04 dB of the
    scan on all 18 bundled path-traced pairs, in about 0.6 of the warm time.
    """
    if options.term_starts == "auto":
        return "transmission" in options.light_terms
    return options.term_starts == "scan"


def plain_model(options: FitOptions) -> FitOptions:
    """The contained model's options: the same fit without light terms."""
    return dataclasses.replace(options, light_terms=(), light_fixed={})


def against_plain(problem, path, result, plain) -> FitResult:
    """Measure what each term adds to the plain fit (``psnr_plain``, ``psnr_without``
    in the terms' record), warn about terms that did not help, and fall back to the
    plain fit when the terms together scored below it."""
    record = dict(result.light_terms)
    layout = problem.param.layout()
    without = {}
    for term, name in LIGHT_UNKNOWNS.items():
        if term in ("law_strength", "thickness_scale") or term not in record:
            continue
        knocked = "law_strength" if term == "law" else name
        if knocked not in layout:
            continue  # a held term: its value is the user's
        first, stop = layout[knocked]
        z = np.asarray(path.z, np.float64).copy()
        z[first:stop] = 0.0
        predictions = evaluate(path.objective, jax.device_put(z), np.asarray(False))["predictions"]
        without[term] = psnr_on_mask(problem, predictions)
    record["psnr_plain"] = plain.psnr
    record["psnr_without"] = without
    messages = list(result.warnings)
    if result.psnr < plain.psnr - WORSE_THAN_PLAIN_DB and not result.interrupted:
        held: dict[str, float | list[float]] = {term: 0.0 for term in AFTER_BLUR if term in record}
        if "law" in record:
            held["law_strength"] = 0.0
        if "fill" in record:
            held["fill"] = 0.0
        if "transmission" in record:
            held["transmission"] = 0.0 if np.ndim(record["transmission"]) == 0 else [0.0] * len(record["transmission"])
        identity = {**record, **held, "psnr_without": {}, "fallback": True}
        identity["stderr"] = {term: None for term in record["stderr"]}
        message = (
            f"light_terms: the fit with {', '.join(sorted(without) or record)} scored "
            f"{plain.psnr - result.psnr:.2g} dB below the plain fit ({result.psnr:.2f} against "
            f"{plain.psnr:.2f} dB): the terms do not describe this pair, and the plain fit is returned, "
            "every term at its identity"
        )
        return dataclasses.replace(plain, light_terms=identity, warnings=(*plain.warnings, message))
    messages.extend(term_bounds(record))
    messages.extend(unlike_any_medium(problem.given, record))
    messages.extend(thickness_unused(problem.given, record))
    for term, value in without.items():
        if result.psnr - value < NEGLIGIBLE_DB:
            messages.append(
                f"light_terms.{term}: adds {result.psnr - value:+.3f} dB to the fit (PSNR {result.psnr:.2f} dB "
                f"with it, {value:.2f} dB with it at its identity): it does not describe this pair; leave it out"
            )
    return dataclasses.replace(result, light_terms=record, warnings=tuple(messages))


#: The law's albedo this close to 0 or 1 is at the edge of its range: the
#: sigmoid that maps it flattens, and the fit pushes on it because the law does
#: not describe the data (an unseen face ended at 0.99993 with the law making
#: the fit 12 dB worse).
ALBEDO_EDGE = 1e-3
#: A gain term this close to -1 darkens to nothing.
GAIN_EDGE = 0.99


def term_bounds(record) -> list[str]:
    """Warnings for light-term values at the edge of their range."""
    out = []
    if "law" in record and "law" not in record["fixed"]:
        w = np.atleast_1d(np.asarray(record["law"], np.float64))
        edge = (w < ALBEDO_EDGE) | (w > 1.0 - ALBEDO_EDGE)
        if edge.any():
            out.append(
                f"light_terms.law: the albedo ended at {'/'.join(f'{x:.5g}' for x in w)}, at the edge of (0, 1): "
                "the law does not describe this pair there, and its standard error is not meaningful"
            )
    for term in ("grazing", "incidence"):
        if term in record and term not in record["fixed"] and float(record[term]) <= -GAIN_EDGE:
            out.append(f"light_terms.{term}: {float(record[term]):.4g} is at its bound -1 (a gain near 0)")
    return out


#: A blended gain further than this outside every medium's (:func:`law_excess`)
#: counts as outside; below it is rounding and the fade's corners.
EXCESS_TOLERANCE = 0.01
#: The share of a light's part of the source (``K`` for the law, ``S - K`` for
#: the fill) that may get a gain no medium gives before the fit warns. On the
#: tuning pairs (2026-11-26) the share was 0 on every fit but the negative fill
#: of pt_face_940_turned (12-15 %).
UNLIKE_ANY_MEDIUM_SHARE = 0.05


def unlike_any_medium(pairs, record) -> list[str]:
    """Warnings for a law (or fill) strength whose blend gives a sizable part of its
    light a gain that neither Lambert's reflection nor the law at any albedo gives.

    A strength in [0, 1] blends two physical laws and never warns. Outside it the
    blend extrapolates, and may still describe a medium: at the albedos the
    procedural heads fit (0.96-0.98) strengths of 1.4-1.9 give gains that lower
    albedos give. The strength is first moved two standard errors towards [0, 1]
    (the least extreme value the data allow); the share is then that of the light
    whose pixels get a gain more than ``EXCESS_TOLERANCE`` outside every medium's
    (:func:`~invsss.forward.light_terms.law_excess`), over all pairs on their masks.
    """
    if "law" not in record:
        return []
    albedo = np.atleast_1d(np.asarray(record["law"], np.float64))
    out = []
    for strength, direction, what in (("law_strength", "light", "the key light's part"),
                                      ("fill", "fill_light", "the other lights' part")):
        if strength not in record or strength in record["fixed"]:
            continue
        a = float(record[strength])
        err = record["stderr"].get(strength)
        nearest = float(np.clip(np.clip(a, 0.0, 1.0), a - 2.0 * (err or 0.0), a + 2.0 * (err or 0.0)))
        if 0.0 <= nearest <= 1.0:
            continue
        outside = total = 0.0
        for pair in pairs:
            if pair.key is None or getattr(pair, direction) is None:
                continue
            part = np.asarray(pair.key if strength == "law_strength" else pair.source - pair.key, np.float64)
            part = np.abs(part) * np.asarray(pair.mask, np.float64)[..., None]
            # law_excess takes the NumPy albedo as it is; its annotation says jax Array.
            excess = np.asarray(law_excess(pair.normal, getattr(pair, direction), albedo, nearest), np.float64)  # type: ignore[arg-type]
            outside += float(np.sum(part * (excess > EXCESS_TOLERANCE)))
            total += float(np.sum(part * np.ones_like(excess)))
        if total > 0 and outside / total > UNLIKE_ANY_MEDIUM_SHARE:
            stated = f"{a:.3g}" + (f" ± {err:.2g}" if err is not None else "")
            out.append(
                f"light_terms.{strength}: at {stated} the blend gives {100 * outside / total:.0f} % of {what} "
                "a gain that neither Lambert's reflection nor the law at any albedo gives (docs/model.md, "
                "section 8): the fit wants a reflection no isotropic medium has, and the albedo is then "
                "not a measurement of the medium"
            )
    return out


#: ``k t`` at the median thickness behind the terminator outside this range: the
#: transmittance is about 1 (every thickness passes the same light) or about 0 (only
#: where the key light meets the surface itself), so the thickness does not shape it.
THICKNESS_USED = (0.01, 100.0)


def thickness_unused(pairs, record) -> list[str]:
    """A warning when the fitted thickness scale leaves the transmittance flat over
    the thicknesses behind the terminator: the term then adds a wrapped light on the
    back side (or at the terminator alone) that does not follow the thickness, and
    its tint is not HDRP's transmission tint."""
    if "thickness_scale" not in record or not np.any(np.asarray(record.get("transmission", 0.0)) > 0.0):
        return []
    median = median_thickness_behind(pairs)
    if median is None:
        return []
    typical = float(record["thickness_scale"]) * median
    low, high = THICKNESS_USED
    if low <= typical <= high:
        return []
    how = ("passes the same light through every thickness" if typical < low
           else "passes light only where the key light meets the surface itself")
    return [
        f"light_terms.thickness_scale: at {float(record['thickness_scale']):.3g}/mm the transmittance {how} "
        f"(k t = {typical:.3g} at the median thickness {median:.3g} mm behind the terminator): "
        "the term does not follow the thickness here, and its tint is not a transmission tint to export"
    ]
