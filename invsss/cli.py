"""The ``invsss`` command line.

Each subcommand is two functions: ``_add_<name>_parser(subparsers)``, which
declares its arguments and sets ``func=_run_<name>``, and ``_run_<name>(args)``,
which does the work and returns an exit code. :func:`build_parser` registers
them with one line each. Bad input surfaces as
:class:`~invsss.validation.InvalidInputError` and is reported by :func:`main`
as ``invsss: error: <message>`` with exit code 2 and no traceback.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from . import __version__
from .io import IMAGE_EXTENSIONS, read_depth, read_image, read_mask, read_params, write_image
from .passes import TAP_WEIGHTS
from .screen_space import MODELS, render
from .validation import InvalidInputError, check_same_size

__all__ = ["build_parser", "main"]


# ------------------------------------------------------------ shared arguments


def _add_model_arguments(parser: argparse.ArgumentParser) -> None:
    """``--model`` and ``--tap-weights``; left unset they fall back to the params file."""
    parser.add_argument(
        "--model",
        choices=MODELS,
        default=None,
        help="screen-space model (default: the params file's 'model', else sog)",
    )
    parser.add_argument(
        "--tap-weights",
        choices=tuple(TAP_WEIGHTS),
        default=None,
        help="7-tap weight set (default: the params file's 'tap_weights', else the "
        "model's own: thesis for thesis, jimenez otherwise)",
    )


def _check_output_path(path: str) -> None:
    """Fail before the work, not after it, when the output cannot be written."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in IMAGE_EXTENSIONS:
        raise InvalidInputError(
            f"{path}: unsupported output extension {ext or '(none)'!r}, "
            f"expected one of {', '.join(IMAGE_EXTENSIONS)}"
        )
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise InvalidInputError(f"{path}: cannot write, directory {directory} does not exist")


def _model_choice(args: argparse.Namespace, extras: dict) -> tuple[str, object]:
    """Model and tap weights: the command-line flag wins over the params file."""
    model = args.model or extras.get("model", "sog")
    tap_weights = args.tap_weights or extras.get("tap_weights")
    return model, tap_weights


# ---------------------------------------------------------------------- render


def _add_render_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "render",
        help="apply screen-space subsurface scattering to an image",
        description="Render subsurface scattering into IMAGE with the parameters in "
        "PARAMS and write the result to OUT (format by extension).",
    )
    parser.add_argument("--image", required=True, help="linear image without scattering")
    parser.add_argument("--depth", required=True, help="depth: float EXR, NPY or 16-bit PNG")
    parser.add_argument("--mask", required=True, help="skin mask, values in [0, 1]")
    parser.add_argument("--params", required=True, help="params JSON file")
    parser.add_argument(
        "--depth-scale",
        type=float,
        default=1.0,
        help="multiplies the stored depth (unit conversion, e.g. 1000 for metres to mm)",
    )
    _add_model_arguments(parser)
    parser.add_argument("--out", required=True, help="output image (.exr, .png, .tif, .jpg, .npy)")
    parser.set_defaults(func=_run_render)


def _run_render(args: argparse.Namespace) -> int:
    _check_output_path(args.out)
    params, extras = read_params(args.params)
    model, tap_weights = _model_choice(args, extras)
    image = read_image(args.image)
    depth = read_depth(args.depth, scale=args.depth_scale)
    mask = read_mask(args.mask)
    check_same_size(image.shape, depth.shape, args.image, args.depth)
    check_same_size(image.shape, mask.shape, args.image, args.mask)
    weights_shape = np.shape(params.weights)
    if len(weights_shape) == 2 and weights_shape[1] not in (1, image.shape[2]):
        raise InvalidInputError(
            f"{args.params}: weights have {weights_shape[1]} columns (one per channel) "
            f"but {args.image} has {image.shape[2]} channel(s)"
        )
    out = render(image, depth, mask, params, model, tap_weights=tap_weights)
    write_image(args.out, np.asarray(out, dtype=np.float32))
    height, width, channels = image.shape
    print(f"wrote {args.out} ({width}x{height}, {channels} channel(s), model {model})")
    return 0


# -------------------------------------------------------------------- fit (estimator helper)
# _add_fit_parser / _run_fit go here.

# ----------------------------------------------------------------- export (export helper)
# _add_export_parser / _run_export go here.


# ------------------------------------------------------------------------ main


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="invsss",
        description="Differentiable inverse rendering of screen-space subsurface scattering.",
    )
    parser.add_argument("--version", action="version", version=f"invsss {__version__}")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND")
    # One registration line per subcommand, in the order `invsss --help` lists them.
    _add_render_parser(subparsers)
    # _add_fit_parser(subparsers)
    # _add_export_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help, --version, or a usage error argparse printed
        return exit_.code if isinstance(exit_.code, int) else 2
    if not hasattr(args, "func"):
        parser.print_usage(sys.stderr)
        print("invsss: error: a command is required", file=sys.stderr)
        return 2
    try:
        return args.func(args)
    except InvalidInputError as err:
        print(f"invsss: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
