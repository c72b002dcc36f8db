"""``invsss render``: apply the model to an image with given parameters."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..forward.light_terms import LIGHT_TERM_FIELDS, NEEDED_BUFFERS, LightBuffers, LightTerms
from ..forward.pair import fill_background_depth
from ..forward.params import DEPTH_UNITS
from ..forward.screen_space import render
from ..io import read_depth, read_image, read_mask, read_params, write_image
from ..runtime.interrupts import StopSignals
from ..validation import InvalidInputError, check_depth, check_same_frame
from .arguments import (
    add_model_arguments,
    add_no_cache_argument,
    check_output_path,
    model_choice,
    read_key_buffer,
    read_light_buffer,
    read_thickness_buffer,
)


def add_parser(subparsers) -> None:
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
    parser.add_argument(
        "--depth-unit", choices=tuple(DEPTH_UNITS), default=None,
        help="unit of the depth after --depth-scale (default: the unit PARAMS records, mm for older files); "
        "another unit than PARAMS's is converted",
    )
    parser.add_argument(
        "--linear-codes",
        action="store_true",
        help="the image's integer codes are linear values: do not decode 8-bit files as sRGB",
    )
    parser.add_argument("--light", metavar="FILE",
                        help="camera-space unit vectors towards the key light, float EXR or NPY (H, W, 3): "
                        "needed when PARAMS holds a fitted 'shift', 'incidence' or 'law' light term")
    parser.add_argument("--normal", metavar="FILE",
                        help="camera-space unit normals, float EXR or NPY (H, W, 3): needed when PARAMS "
                        "holds a fitted 'grazing', 'incidence' or 'law' light term")
    parser.add_argument("--key", metavar="FILE",
                        help="the image lit by the key light alone, the image's size and channels: needed "
                        "when PARAMS holds a fitted 'law' light term (with --normal and --light)")
    parser.add_argument("--fill-light", metavar="FILE",
                        help="camera-space unit vectors towards the other lights, float EXR or NPY "
                        "(H, W, 3): needed when PARAMS holds a fitted 'fill' light term")
    parser.add_argument("--thickness", metavar="FILE",
                        help="mm the key light travels inside the skin, float EXR or NPY (H, W): needed when "
                        "PARAMS holds a fitted 'transmission' light term")
    parser.add_argument("--key-irradiance", metavar="FILE",
                        help="the albedo times the key light's unshadowed irradiance, the image's size and "
                        "channels: needed when PARAMS holds a fitted 'transmission' light term")
    parser.add_argument("--no-light-terms", action="store_true",
                        help="render the blur alone, leaving out the light terms PARAMS may hold")
    add_model_arguments(parser)
    parser.add_argument("--out", required=True, help="output image (.exr, .png, .tif, .jpg, .npy)")
    add_no_cache_argument(parser)
    parser.set_defaults(func=run)


def _listed(words: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} and {words[-1]}"


def _render_light_terms(args, extras, image):
    """The light terms of PARAMS (None without them, or with --no-light-terms) and
    the buffers they need, read and checked."""
    record = None if args.no_light_terms else extras.get("light_terms")
    if not record:
        return None, None
    shape = image.shape[:2]
    terms = LightTerms(**{term: record[term] for term in LIGHT_TERM_FIELDS if term in record})
    terms.check(f"{args.params}: light_terms")
    buffers = {}
    # A term at its identity (a fit that fell back to the plain model) needs no buffer.
    # Every missing buffer is named at once, not one per attempt.
    missing = [flag for flag in dict.fromkeys(f for t in terms.used for f in NEEDED_BUFFERS[t])
               if getattr(args, flag) is None]
    if missing:
        lacking = [t for t in terms.used if set(NEEDED_BUFFERS[t]) & set(missing)]
        which = (f"the {lacking[0]!r} light term, which needs" if len(lacking) == 1
                 else f"the {_listed([repr(t) for t in lacking])} light terms, which need")
        raise InvalidInputError(
            f"{args.params}: holds {which} {_listed(['--' + f.replace('_', '-') for f in missing])} "
            f"(or --no-light-terms to render without the light terms)"
        )
    for term in terms.used:
        for flag in NEEDED_BUFFERS[term]:
            path = getattr(args, flag)
            if flag in ("key", "key_irradiance") and flag not in buffers:
                buffers[flag] = read_key_buffer(path, image, args.linear_codes, "--" + flag.replace("_", "-"))
            elif flag == "thickness" and flag not in buffers:
                buffers[flag] = read_thickness_buffer(path, shape)
            elif flag not in buffers:
                buffers[flag] = read_light_buffer(path, flag.replace("_", "-"), shape)
    return terms, LightBuffers(**buffers)


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    check_output_path(args.out)
    params, extras = read_params(args.params)
    model, tap_weights = model_choice(args, extras)
    image = read_image(args.image, linear=args.linear_codes)
    depth = read_depth(args.depth, scale=args.depth_scale)
    fitted_unit = extras.get("depth_unit", "mm")
    if args.depth_unit is not None and args.depth_unit != fitted_unit:
        # The depth goes into the parameters' unit: the blur, the light terms' shift and
        # the plausibility check then all read one unit.
        depth = depth * (DEPTH_UNITS[args.depth_unit] / DEPTH_UNITS[fitted_unit])
        print(f"invsss: depth in {args.depth_unit} converted to {fitted_unit}, the unit {args.params} was "
              "fitted in", file=sys.stderr)
    mask = read_mask(args.mask)
    check_same_frame([(args.image, image), (args.depth, depth), (args.mask, mask)])
    # A renderer's 0/inf background is fine off the mask; filled before any use.
    check_depth(depth, mask.shape, args.depth, mask)
    depth = fill_background_depth(depth)
    weights_shape = np.shape(params.weights)
    if len(weights_shape) == 2 and weights_shape[1] not in (1, image.shape[2]):
        raise InvalidInputError(
            f"{args.params}: weights have {weights_shape[1]} columns (one per channel) "
            f"but {args.image} has {image.shape[2]} channel(s)"
        )
    terms, buffers = _render_light_terms(args, extras, image)
    # render takes the NumPy arrays as they are (it converts them); its annotations say jax Array.
    out = render(image, depth, mask, params, model, tap_weights=tap_weights, light_terms=terms,  # type: ignore[arg-type]
                 light_buffers=buffers)
    write_image(args.out, np.asarray(out, dtype=np.float32))
    height, width, channels = image.shape
    extra = "" if terms is None else ", light terms " + ", ".join(
        f"{term}={_term_value(terms, term)}" for term in LIGHT_TERM_FIELDS if term in extras["light_terms"])
    print(f"wrote {args.out} ({width}x{height}, {channels} channel(s), model {model}{extra})")
    return 0


def _term_value(terms, term: str) -> str:
    """A light term's value as the CLI prints it ("0.93/0.8/0.7" for a law per channel)."""
    return "/".join(f"{v:g}" for v in np.atleast_1d(np.asarray(getattr(terms, term), np.float64)))


#: Parameters ``--fix`` accepts: one number each, or a comma-separated list.


