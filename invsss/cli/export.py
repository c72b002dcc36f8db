"""``invsss export``: a params file as shader constants for a renderer."""

from __future__ import annotations

import argparse
import sys


from ..runtime.interrupts import StopSignals
from ..io.export import EXPORT_FORMATS, export_params
from .arguments import add_model_arguments


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "export",
        help="write a params file's constants for a real-time shader (JSON or HLSL)",
        description="Turn the parameters in PARAMS into the constants a real-time shader "
        "uses (per-pass widths, tap offsets and weights, layer blend factors, or the "
        "separable kernel) and print them, or write them to --out.",
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
                        help="output file (default: standard output)")
    parser.add_argument("--with-shader", action="store_true",
                        help="with --format hlsl and --out: also write the reference shader "
                        "(invsss_*.hlsl, docs/renderer.md) beside FILE, including it")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    text = export_params(
        args.params, args.out, args.format, model=args.model, tap_weights=args.tap_weights,
        taps=args.taps, strength=args.strength, with_shader=args.with_shader,
    )
    if args.out is None:
        sys.stdout.write(text)
    else:
        print(f"wrote {args.out} ({args.format})")
        if args.with_shader:
            print("wrote the reference shader beside it (docs/renderer.md)")
    return 0
