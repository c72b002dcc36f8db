"""``invsss profile``: measure a diffusion profile from a spot-lit photograph."""

from __future__ import annotations

import argparse
import json
import os
import tempfile

import numpy as np

from ..io import read_image
from ..runtime.interrupts import StopSignals
from ..validation import InvalidInputError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "profile",
        help="measure a diffusion profile from a spot-lit skin image and a white reference",
        description="Measure R(r) from SKIN (skin or a slab lit by a small spot) and REF (a "
        "white Lambertian reference, e.g. Spectralon, under the same spot and exposure; "
        "thesis 4.1), fit a sum of Gaussians and Jensen's dipole, and write OUT as a "
        "profile JSON for `invsss fit --profile OUT`. The dipole's sigma_s' and sigma_a "
        "and the samples are stored under \"fit\".",
    )
    parser.add_argument("skin", help="linear image of the spot-lit skin")
    parser.add_argument("reference", metavar="REF", help="linear image of the lit white reference")
    parser.add_argument("--out", required=True, help="profile JSON to write (refused if it exists)")
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
                        help="divide by this spot area (default: the lit area seen on REF, "
                        "which makes R absolute in mm^-2, as the dipole fit needs)")
    parser.add_argument("--saturation", type=float, default=None, metavar="LEVEL",
                        help="values at or above this are overexposed (default: no check; "
                        "1 for clipped [0, 1] photos, 255 for 8-bit counts)")
    parser.add_argument("--black-level", type=float, default=0.0, metavar="LEVEL",
                        help="camera offset subtracted from both images (default: 0)")
    parser.add_argument("--gaussians", type=int, default=3, metavar="K",
                        help="number of Gaussians in the fitted profile (default: 3)")
    parser.add_argument("--eta", type=float, default=1.3,
                        help="relative index of refraction for the dipole fit (default: 1.3)")
    parser.add_argument("--linear-codes", action="store_true",
                        help="8/16-bit codes are linear, not sRGB")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    from ..measurement.dipole_fit import fit_dipole
    from ..measurement.measure import measure_profile

    if os.path.exists(args.out):
        raise InvalidInputError(f"{args.out}: already exists; remove it or choose another --out")
    if not os.path.isdir(os.path.dirname(os.path.abspath(args.out))):
        raise InvalidInputError(f"{args.out}: cannot write, its directory does not exist")
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
                                    **options).lit_area_mm2
    measured = measure_profile(skin, reference, centre, args.mm_per_pixel, names=names,
                               spot_area_mm2=spot_area, **options)
    gaussians = measured.fit(args.gaussians)
    dipole = fit_dipole(measured.r_mm, measured.reflectance, eta=args.eta)
    content = gaussians.to_dict()
    content["source"] = f"measured by invsss profile from {args.skin} and {args.reference}"
    content["fit"]["dipole"] = dipole.to_dict()
    content["fit"]["measurement"] = {
        "mm_per_pixel": args.mm_per_pixel, "centre": list(measured.centre),
        "spot_area_mm2": spot_area, "lit_area_mm2": measured.lit_area_mm2,
        "lit_radius_mm": measured.lit_radius_mm, **options,
        "r_mm": measured.r_mm.tolist(), "reflectance": np.asarray(measured.reflectance).tolist(),
    }
    text = json.dumps(content, indent=2) + "\n"
    folder = os.path.dirname(os.path.abspath(args.out))
    with tempfile.NamedTemporaryFile("w", dir=folder, suffix=".tmp", delete=False) as handle:
        handle.write(text)
    os.replace(handle.name, args.out)  # never a half-written profile under the real name
    ss, sa = (np.round(np.asarray(x, dtype=float), 4).tolist()
              for x in (dipole.sigma_s_prime, dipole.sigma_a))
    print(f"profile: {measured.r_mm.size} samples from {measured.r_mm[0]:.2f} to "
          f"{measured.r_mm[-1]:.2f} mm; {args.gaussians} Gaussians (rms {float(gaussians.rms):.3f}); "
          f"dipole sigma_s' {ss} /mm, sigma_a {sa} /mm; wrote {args.out}")
    return 0
