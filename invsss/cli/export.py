"""``invsss export``: a params file as shader constants for a renderer."""

from __future__ import annotations

import argparse
import os
import sys

from ..io import read_params
from ..io.export import EXPORT_FORMATS, export_params, shader_files
from ..runtime.interrupts import StopSignals
from ..validation import InvalidInputError
from .arguments import add_model_arguments, model_choice


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write a params file's constants for a real-time shader (JSON or HLSL), or a "
        "burley fit as an engine's profile asset (HDRP, Unreal)",
        description="Turn the parameters in PARAMS into the constants a real-time shader "
        "uses (per-pass widths, tap offsets and weights, layer blend factors, or the "
        "separable kernel) and print them, or write them to --out. --format hdrp or unreal "
        "writes the engine's profile asset instead, from a fit with --model burley.",
    )
    parser.add_argument("params", help="params JSON file")
    parser.add_argument(
        "--format", choices=EXPORT_FORMATS, default="json", help="output format (default: json)"
    )
    add_model_arguments(parser)
    parser.add_argument("--taps", type=int, default=17,
                        help="separable only: kernel taps, odd (default: 17)")
    parser.add_argument("--strength", type=float, default=1.0,
                        help="separable only: blend of the kernel with the identity (default: 1)")
    parser.add_argument("--out", default=None, metavar="FILE",
                        help="output file (default: standard output); a file that is already there "
                        "is refused unless --overwrite is given")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace --out, and with --with-shader the shader files, when they are "
                        "already there (other files beside them are kept)")
    # The engines' profile assets (invsss.io.engine_profiles).
    parser.add_argument("--mm-per-unit", type=float, default=None,
                        help="hdrp/unreal: millimetres per unit of the fitted pair's depth (default: from the "
                        "depth_unit PARAMS records, mm for older files)")
    parser.add_argument("--accept-assumed", action="store_true",
                        help="hdrp/unreal: write Burley's d even where the fit held it or left it undetermined, "
                        "marked as assumed in the output (refused otherwise)")
    parser.add_argument("--albedo", default=None, metavar="A or R/G/B",
                        help="unreal: surface albedo for the mean-free-path conversion (default: Unreal's "
                        "default, reported as undetermined)")
    parser.add_argument("--world-scale", type=float, default=None,
                        help="hdrp: worldScale (m per unit); unreal: WorldUnitScale (default: the engine's, "
                        "reported as undetermined)")
    parser.add_argument("--thickness-map-mm", type=float, default=None, metavar="MM",
                        help="hdrp, for a fit with the transmission term: the thickness in mm that the "
                        "material's thickness map's 1 stands for (default 5, HDRP's default remap, reported as "
                        "undetermined); the exported thicknessRemap scales with it")
    parser.add_argument("--thickness-range-mm", default=None, metavar="LO,HI",
                        help="unreal, for a fit with the transmission term: the thicknesses in mm over which "
                        "the transmission tint is matched (default 1,10, reported as undetermined)")
    parser.add_argument("--with-shader", action="store_true",
                        help="with --format hlsl and --out: also write the reference shader "
                        "(invsss_*.hlsl, docs/renderer.md) beside FILE, including it")
    parser.set_defaults(func=run)


def _engine_options(args) -> dict | None:
    """The hdrp/unreal options of ``invsss export``; None for the shader formats."""
    if args.format not in ("hdrp", "unreal"):
        return None
    albedo = None
    if args.albedo is not None:
        try:
            albedo = [float(a) for a in args.albedo.split("/")]
        except ValueError:
            raise InvalidInputError(f"--albedo: expected a number or R/G/B numbers, got {args.albedo!r}") from None
    thickness_range = None
    if args.thickness_range_mm is not None:
        try:
            thickness_range = tuple(float(x) for x in args.thickness_range_mm.split(","))
        except ValueError:
            thickness_range = ()
        if len(thickness_range) != 2 or not 0.0 < thickness_range[0] < thickness_range[1]:
            raise InvalidInputError(
                f"--thickness-range-mm: expected LO,HI in mm with 0 < LO < HI, got {args.thickness_range_mm!r}")
    return {"mm_per_unit": args.mm_per_unit, "albedo": albedo, "world_scale": args.world_scale,
            "accept_assumed": args.accept_assumed, "thickness_map_mm": args.thickness_map_mm,
            "thickness_range_mm": thickness_range}


def _checked_albedo(engine: dict | None) -> dict | None:
    """Refuse an ``--albedo`` of a count other than one or three (R/G/B) in one line."""
    albedo = (engine or {}).get("albedo")
    if albedo is not None and len(albedo) not in (1, 3):
        raise InvalidInputError(
            f"--albedo: expected one number or three (R/G/B), got {len(albedo)} ({'/'.join(map(str, albedo))})"
        )
    return engine


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    if args.overwrite and args.out is None:
        raise InvalidInputError("--overwrite: replaces an --out file; without --out nothing is written")
    text = export_params(
        args.params, args.out, args.format, model=args.model, tap_weights=args.tap_weights,
        taps=args.taps, strength=args.strength, with_shader=args.with_shader,
        engine=_checked_albedo(_engine_options(args)), overwrite=args.overwrite,
    )
    if args.out is None:
        sys.stdout.write(text)
    else:
        print(f"wrote {args.out} ({args.format})")
        if args.with_shader:
            # The files export_params wrote beside the constants, by name.
            _, extras = read_params(args.params)
            model, _ = model_choice(args, extras)
            names = [os.path.basename(p) for p in shader_files(args.out, model, extras.get("light_terms"))]
            print(f"wrote the {model} reference shader beside it: {', '.join(names)} (docs/renderer.md)")
    return 0
