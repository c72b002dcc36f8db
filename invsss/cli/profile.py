"""``invsss profile``: measure a diffusion profile from a spot-lit photograph."""

from __future__ import annotations

import argparse
import json

import numpy as np

from ..io import read_image
from ..io.writing import check_file_target, same_file, write_text_atomic
from ..measurement.medium_fit import MODEL_NAMES
from ..measurement.profile_models import PROFILE_MODELS
from ..measurement.transport_table import ONE_MINUS_ALPHA
from ..runtime.interrupts import StopSignals
from ..validation import InvalidInputError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "profile",
        help="measure a diffusion profile from a spot-lit skin image and a white reference",
        description="Measure R(r) from SKIN (skin or a slab lit by a small spot) and REF (a "
        "white Lambertian reference, e.g. Spectralon, under the same spot and exposure; "
        "thesis 4.1), fit a sum of Gaussians and the medium (sigma_s', sigma_a, Burley's d and "
        "albedo, with standard errors from the samples' noise, on the radii above the spot, the "
        "resolution and the noise floor), and write OUT as a profile JSON for `invsss fit "
        "--profile OUT`. The medium, the dipole's reading and the samples are stored under "
        "\"fit\".",
    )
    parser.add_argument("skin", help="linear image of the spot-lit skin")
    parser.add_argument("reference", metavar="REF", help="linear image of the lit white reference")
    parser.add_argument("--out", required=True, help="profile JSON to write (refused if it exists, unless --overwrite)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace an existing --out file (never one of the input images)")
    parser.add_argument("--mm-per-pixel", type=float, required=True, metavar="MM",
                        help="pixel pitch on the skin, mm")
    parser.add_argument("--centre", type=float, nargs=2, default=None, metavar=("ROW", "COL"),
                        help="spot centre in SKIN, pixels (default: centroid of its bright spot)")
    parser.add_argument("--direction", default="right", choices=["right", "left", "down", "up"],
                        help="where the sample band runs from the centre (default: right)")
    parser.add_argument("--averaging", default="radial", choices=["radial", "column"],
                        help="radial bins (default) or the thesis's column means")
    parser.add_argument("--band-width-mm", type=float, default=5.0, metavar="MM",
                        help="width of the sample band (default: 5, the thesis's)")
    parser.add_argument("--filter-factor", type=float, default=10.0, metavar="F",
                        help="how much a filter dimmed REF against SKIN (default: 10, the "
                        "thesis's; 1 when both were taken alike, as in a rendered pair)")
    parser.add_argument("--lit-radius-mm", type=float, default=None, metavar="MM",
                        help="leave out distances below this (default: the lit spot's extent "
                        "on REF); a few spot radii keeps the spot's own size out of the fit")
    parser.add_argument("--max-radius-mm", type=float, default=None, metavar="MM",
                        help="leave out distances above this (default: the image border)")
    parser.add_argument("--spot-area-mm2", type=float, default=None, metavar="MM2",
                        help="divide by this spot area (default: the spot's area from its power "
                        "on REF, partly lit edge pixels included, which makes R absolute in "
                        "mm^-2, as the medium fit needs)")
    parser.add_argument("--saturation", type=float, default=None, metavar="LEVEL",
                        help="values at or above this are overexposed (default: no check; "
                        "1 for clipped [0, 1] photos, 255 for 8-bit counts)")
    parser.add_argument("--black-level", type=float, default=0.0, metavar="LEVEL",
                        help="camera offset subtracted from both images (default: 0)")
    parser.add_argument("--gaussians", type=int, default=3, metavar="K",
                        help="number of Gaussians in the fitted profile (default: 3)")
    parser.add_argument("--eta", type=float, default=1.3,
                        help="relative index of refraction of the skin's surface (default: 1.3; "
                        "the transport models have tables for 1.0 and 1.3)")
    parser.add_argument("--model", default="transport", choices=list(MODEL_NAMES),
                        help="profile model of the medium fit (default: transport, what a camera "
                        "on the axis of a focused spot reads; transport-diffuse for a diffuse "
                        "source on the skin, transport-diffuse-rough through a rough (Beckmann "
                        "0.5) surface; the published ones give the exitance and misread a "
                        "photograph: docs/capture.md, 'The spot measurement')")
    parser.add_argument("--min-snr", type=float, default=3.0, metavar="SNR",
                        help="noise floor: trust samples out to where R / stderr falls below "
                        "this (default: 3)")
    parser.add_argument("--format", default=None, choices=["hdrp", "unreal"],
                        help="also write the engine's profile values of the measured medium under "
                        "\"fit\".\"engine\": HDRP's Diffusion Profile (Burley's d) or Unreal's "
                        "Subsurface Profile (d and the surface albedo), as `invsss export` writes them")
    parser.add_argument("--linear-codes", action="store_true",
                        help="8/16-bit codes are linear, not sRGB")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    from ..measurement.dipole_fit import fit_dipole
    from ..measurement.measure import measure_profile

    # Never an input, --overwrite or not; then the checks every file output gets.
    for flag, given in (("SKIN", args.skin), ("REF", args.reference)):
        if same_file(given, args.out):
            raise InvalidInputError(f"{args.out}: is the input {flag} of this run; choose another --out")
    check_file_target(args.out, overwrite=args.overwrite, role="the profile JSON")
    try:  # before reading anything: the transport models have tables for some eta only
        PROFILE_MODELS[args.model](np.ones(1), 1.0, 0.1, args.eta)
    except ValueError as error:
        why = str(error).removeprefix("eta: ")
        raise InvalidInputError(
            f"--eta: {why} (--model {args.model}); give a tabulated eta or another --model") from None
    skin = read_image(args.skin, linear=args.linear_codes)
    reference = read_image(args.reference, linear=args.linear_codes)
    options = dict(
        band_width_mm=args.band_width_mm, filter_factor=args.filter_factor,
        direction=args.direction, averaging=args.averaging, saturation=args.saturation,
        lit_radius_mm=args.lit_radius_mm, max_radius_mm=args.max_radius_mm,
        black_level=args.black_level,
    )
    # Errors about either image name its file, not the library's argument names.
    names = (args.skin, args.reference)
    centre = tuple(args.centre) if args.centre else None
    spot_area = args.spot_area_mm2
    if spot_area is None:
        # The lit area is only known after reading REF: a first pass measures it.
        spot_area = measure_profile(skin, reference, centre, args.mm_per_pixel, names=names,
                                    **options).spot_area_mm2
    measured = measure_profile(skin, reference, centre, args.mm_per_pixel, names=names,
                               spot_area_mm2=spot_area, **options)
    gaussians = measured.fit(args.gaussians)
    medium, trusted = _fit_medium(measured, args)
    # The dipole's reading, kept for comparison (docs/capture.md), on the samples every
    # channel trusts.
    both = np.asarray(trusted.mask).reshape(measured.r_mm.size, -1).all(axis=1)
    dipole = fit_dipole(measured.r_mm[both], measured.reflectance[both], eta=args.eta)
    content = gaussians.to_dict()
    content["source"] = f"measured by invsss profile from {args.skin} and {args.reference}"
    content["fit"]["medium"] = {**medium.to_dict(), "r_min_mm": np.asarray(trusted.r_min_mm).tolist(),
                                "r_max_mm": np.asarray(trusted.r_max_mm).tolist(),
                                "trusted": list(trusted.reasons)}
    content["fit"]["dipole"] = dipole.to_dict()
    if args.format:
        content["fit"]["engine"] = _engine_fields(medium, args.format)
    content["fit"]["measurement"] = {
        "mm_per_pixel": args.mm_per_pixel, "centre": list(measured.centre),
        "spot_area_mm2": spot_area, "lit_area_mm2": measured.lit_area_mm2,
        "lit_radius_mm": measured.lit_radius_mm, **options,
        "r_mm": measured.r_mm.tolist(), "reflectance": np.asarray(measured.reflectance).tolist(),
        "reflectance_stderr": np.nan_to_num(np.asarray(measured.reflectance_stderr), nan=-1.0).tolist(),
    }
    write_text_atomic(args.out, json.dumps(content, indent=2) + "\n")  # never a half-written profile
    print(f"profile: {measured.r_mm.size} samples from {measured.r_mm[0]:.2f} to "
          f"{measured.r_mm[-1]:.2f} mm; {args.gaussians} Gaussians (rms {float(gaussians.rms):.3f}); "
          f"wrote {args.out}")
    for line in _medium_lines(medium, trusted):
        print(line)
    if args.format:
        print(f"{args.format}: {json.dumps(content['fit']['engine']['fields'])}")
    return 0


def _engine_fields(medium, format):
    """The engine's profile values of the measured medium: Burley's d (and albedo for Unreal)."""
    from ..io.engine_profiles import hdrp_profile, unreal_profile

    d = np.atleast_1d(np.asarray(medium.burley_d, np.float64))
    if format == "hdrp":
        fields = hdrp_profile(d)
    else:
        fields = unreal_profile(d, albedo=np.clip(np.atleast_1d(medium.burley_albedo), 0.01, 1.0))
    return {"format": format, "fields": fields, "burley_d_mm": d.tolist(),
            "burley_albedo": np.atleast_1d(medium.burley_albedo).tolist(),
            "note": "d and the albedo of the measured medium (Burley's searchlight fits); the scene's "
                    "unit (worldScale, WorldUnitScale) is the default, set it for your scene"}


def _fit_medium(measured, args):
    """The medium fit of each channel on its trusted samples, and the trusted radii."""
    from ..measurement.medium_fit import MediumFit, fit_medium
    from ..measurement.trusted_radii import trusted_radii

    trusted = trusted_radii(measured, args.mm_per_pixel, min_snr=args.min_snr)
    y = np.asarray(measured.reflectance)
    err = np.asarray(measured.reflectance_stderr)
    single = y.ndim == 1
    columns, errors, masks = (a[:, None] if single else a for a in (y, err, np.asarray(trusted.mask)))
    fits = []
    for c in range(columns.shape[1]):
        keep = masks[:, c]
        if np.count_nonzero(keep) < 3:
            raise InvalidInputError(
                f"{args.skin}: only {np.count_nonzero(keep)} trusted sample(s) in channel {c} "
                f"({'; '.join(trusted.reasons)}); lower --min-snr or --lit-radius-mm")
        # A noise-free image's bins can have no scatter at all: floor the error at 1e-6 of R.
        floor = np.maximum(errors[keep, c], 1e-6 * columns[keep, c])
        fits.append(fit_medium(measured.r_mm[keep], columns[keep, c], model=args.model, eta=args.eta,
                               stderr=floor))
    if single:
        return fits[0], trusted
    stacked = {k: np.array([getattr(f, k) for f in fits]) for k in MediumFit.__dataclass_fields__
               if k not in ("model", "eta")}
    return MediumFit(**stacked, model=args.model, eta=fits[0].eta), trusted


def _medium_lines(medium, trusted):
    def pm(value, error, digits):
        v, e = np.atleast_1d(value), np.atleast_1d(error)
        return ", ".join(f"{a:.{digits}f} +- {b:.{digits}f}" for a, b in zip(v, e))

    lines = []
    if medium.model.startswith("transport"):
        alpha = np.atleast_1d(medium.sigma_s_prime) / (np.atleast_1d(medium.sigma_s_prime)
                                                       + np.atleast_1d(medium.sigma_a))
        low, high = 1.0 - max(ONE_MINUS_ALPHA), 1.0 - min(ONE_MINUS_ALPHA)
        if np.any((alpha < low) | (alpha > high)):
            lines.append(f"note: albedo {', '.join(f'{a:.4f}' for a in alpha)} lies outside the transport "
                         f"table's {low:.3f}-{high:.3f}: the reading there is extrapolated")
    return lines + [
        f"medium ({medium.model}, eta {medium.eta:g}): "
        f"sigma_s' {pm(medium.sigma_s_prime, medium.sigma_s_prime_stderr, 4)} /mm, "
        f"sigma_a {pm(medium.sigma_a, medium.sigma_a_stderr, 5)} /mm",
        f"Burley: d {pm(medium.burley_d, medium.burley_d_stderr, 3)} mm, albedo "
        f"{pm(medium.burley_albedo, medium.burley_albedo_stderr, 3)}; reduced chi2 "
        f"{', '.join(f'{v:.2f}' for v in np.atleast_1d(medium.reduced_chi2))}",
        "trusted radii: " + ", ".join(f"{a:.2f}-{b:.2f} mm" for a, b in
                                      zip(np.atleast_1d(trusted.r_min_mm), np.atleast_1d(trusted.r_max_mm)))
        + " (" + "; ".join(trusted.reasons) + ")",
    ]
