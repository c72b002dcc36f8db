"""The ``invsss`` command line.

Each subcommand is two functions: ``_add_<name>_parser(subparsers)``, which
declares its arguments and sets ``func=_run_<name>``, and ``_run_<name>(args, stop)``,
which does the work and returns an exit code. :func:`build_parser` registers
them with one line each.

Exit codes, all without a traceback:

* 0: done;
* 1: the work was done but its output could not be written (the fit's estimate
  is then saved elsewhere and the message says where), or a sweep ran to its
  end but some of its trials failed (each failure is in ``sweep-report``);
* 2: bad input, reported as ``invsss: error: <message>`` (an
  :class:`~invsss.validation.InvalidInputError`), or an output directory that
  already holds a result (``--overwrite``) or is in use by another run;
* 130 / 143: interrupted by SIGINT (Ctrl-C) / SIGTERM (:mod:`invsss.runtime.interrupts`).
  ``fit`` then writes the best estimate so far, marked ``"interrupted": true``,
  when at least one solver step has finished.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import signal
import sys
import tempfile
import threading
import time
import warnings

import numpy as np

from .. import __version__
from ..runtime.determinism import use_deterministic_scheduler
from ..estimator import FitInterrupted, fit_pair, fit_pairs
from ..runtime.interrupts import Interrupted, StopSignals
from ..estimator.options import check_canvas
from ..estimator.parametrisation import GAUGES
from ..estimator.solve import SOLVERS
from ..io.export import EXPORT_FORMATS, export_params
from ..io import (
    image_extension,
    read_depth,
    read_image,
    read_mask,
    read_params,
    shared_clipping_level,
    write_image,
    write_params,
)
from ..forward.passes import TAP_WEIGHTS
from ..forward.profiles import PROFILE_NAMES
from ..io.result_dir import ResultDir, ResultWriteError
from ..forward.screen_space import MODELS, render
from ..forward.params import check_plausible
from ..forward.light_terms import LIGHT_TERM_FIELDS, LIGHT_TERM_NAMES, NEEDED_BUFFERS, LightBuffers, LightTerms
from ..forward.pair import ImagePair, fill_background_depth
from .. import photo_pair  # issue 33
from ..validation import InvalidInputError, check_depth, check_same_frame

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
    image_extension(path, "output")
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
    parser.add_argument("--no-light-terms", action="store_true",
                        help="render the blur alone, leaving out the light terms PARAMS may hold")
    _add_model_arguments(parser)
    parser.add_argument("--out", required=True, help="output image (.exr, .png, .tif, .jpg, .npy)")
    _add_no_cache_argument(parser)
    parser.set_defaults(func=_run_render)


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
    for term in terms.used:
        for flag in NEEDED_BUFFERS[term]:
            path = getattr(args, flag)
            if path is None:
                raise InvalidInputError(
                    f"{args.params}: holds the {term!r} light term, which needs --{flag} "
                    f"(or --no-light-terms to render without the light terms)"
                )
            if flag == "key" and flag not in buffers:
                buffers[flag] = _read_key_buffer(path, image, args.linear_codes)
            elif flag not in buffers:
                buffers[flag] = _read_light_buffer(path, flag, shape)
    return terms, LightBuffers(**buffers)


def _read_light_buffer(path, flag: str, shape):
    """A --light or --normal buffer, read as linear floats, of the image's size."""
    buffer = read_image(path, linear=True)
    if buffer.shape != (*shape, 3):
        raise InvalidInputError(
            f"{path}: expected a 3-channel image of the source's size {shape} for --{flag}, got shape {buffer.shape}"
        )
    return buffer


def _read_key_buffer(path, source, linear_codes: bool):
    """A --key image (the source lit by the key light alone), read as the source is,
    of the source's size and channels."""
    source = np.asarray(source)
    # A grey source stored as RGB was read as one channel before a grey target: its key too.
    key = read_image(path, linear=linear_codes, grey=source.ndim == 2 or source.shape[-1] == 1)
    wanted = source.shape if source.ndim == 3 else (*source.shape, 1)
    key = key if key.ndim == 3 else key[..., None]
    if key.shape != wanted:
        raise InvalidInputError(
            f"{path}: expected an image of the source's size and channels {wanted} for --key, got shape {key.shape}"
        )
    return key


def _run_render(args: argparse.Namespace, stop: StopSignals) -> int:
    _check_output_path(args.out)
    params, extras = read_params(args.params)
    model, tap_weights = _model_choice(args, extras)
    image = read_image(args.image, linear=args.linear_codes)
    depth = read_depth(args.depth, scale=args.depth_scale)
    mask = read_mask(args.mask)
    check_same_frame([(args.image, image), (args.depth, depth), (args.mask, mask)])
    # A renderer's 0/inf background is fine off the mask; filled before any use.
    check_depth(depth, mask.shape, args.depth, mask)
    depth = fill_background_depth(depth)
    check_plausible(params, depth, args.params)
    weights_shape = np.shape(params.weights)
    if len(weights_shape) == 2 and weights_shape[1] not in (1, image.shape[2]):
        raise InvalidInputError(
            f"{args.params}: weights have {weights_shape[1]} columns (one per channel) "
            f"but {args.image} has {image.shape[2]} channel(s)"
        )
    terms, buffers = _render_light_terms(args, extras, image)
    out = render(image, depth, mask, params, model, tap_weights=tap_weights, light_terms=terms,
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


# -------------------------------------------------------------------- fit


#: Parameters ``--fix`` accepts: one number each, or a comma-separated list.
_FIX_SCALARS = ("sss_level", "correction", "maxdd")
_FIX_LISTS = ("weights", "variances")
_PAIR_FLAGS = ("source", "target", "depth", "mask")


def _add_no_cache_argument(parser) -> None:
    """``--no-cache``, for the commands that compile (see :func:`_use_compile_cache`)."""
    parser.add_argument("--no-cache", action="store_true",
                        help="do not use the persistent compilation cache (also INVSSS_NO_CACHE=1); it "
                        "lives in ~/.cache/invsss/jax or $XDG_CACHE_HOME/invsss/jax, and "
                        "INVSSS_CACHE_DIR moves it")


def _add_fit_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "fit",
        help="estimate the scattering parameters from source/target image pairs",
        description="Fit the screen-space SSS parameters that turn SOURCE into TARGET. "
        "Repeat --source/--target/--depth/--mask (the same number of times, matched in "
        "order) to fit one set of parameters to several pairs. Writes DIR/params.json "
        "(the estimate, its standard errors and the fit report; written first), "
        "DIR/fit.exr (the fitted prediction; fit_0.exr, fit_1.exr, ... for several "
        "pairs), DIR/report.png (images, residuals, convergence, parameters) and "
        "DIR/invsss-manifest.json (which files make the result, and whether it is "
        "complete; docs/outputs.md).",
    )
    parser.add_argument("--source", action="append", required=True,
                        help="linear image without scattering (repeat for several pairs)")
    parser.add_argument("--target", action="append", required=True,
                        help="linear photograph to match, 1 or 3 channels (repeat)")
    # --- issue 33: photographs without a 3D model (invsss/io/photo_pair.py) ---
    parser.add_argument("--depth", action="append", default=[],
                        help="eye-space depth in mm: float EXR or NPY, or a 16-bit PNG whose integer codes are "
                        "read as mm (times --depth-scale) (repeat; or give --distance)")
    parser.add_argument("--distance", action="append", default=[], type=float, metavar="MM",
                        help="instead of --depth: the face's distance from the camera in mm, one depth for the "
                        "whole face; correction and maxdd then have no effect and are held (at 0 and 1 unless "
                        "--fix gives them; params.json's inputs.held says so) (once, or once per pair)")
    parser.add_argument("--mask", action="append", default=[],
                        help="skin mask, values in [0, 1] (repeat); without it a mask is made from the pair "
                        "and written to DIR/mask_used.png (docs/capture.md)")
    # --- end issue 33 ---
    parser.add_argument(
        "--depth-scale",
        type=float,
        default=1.0,
        help="multiplies every stored depth (unit conversion, e.g. 1000 for metres to mm)",
    )
    parser.add_argument("--model", choices=MODELS, default="sog", help="screen-space model (default: sog)")
    parser.add_argument(
        "--profile",
        default="thesis-nir",
        metavar="NAME|FILE.json",
        help=f"sum-of-Gaussians profile ({', '.join(PROFILE_NAMES)}, or a JSON file); its "
        "variances are fixed in the default gauge (default: thesis-nir)",
    )
    parser.add_argument(
        "--gauge",
        choices=GAUGES,
        default="variances",
        help="which side of the sss_level/variance-scale degeneracy is fixed: the "
        "profile's variances (default), or sss_level (then give --fix sss_level=VALUE)",
    )
    parser.add_argument(
        "--fix",
        action="extend",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="hold parameters at given values: sss_level, correction, maxdd take one "
        "number, weights and variances a comma-separated list "
        "(e.g. --fix maxdd=0.05 variances=0.5,2,8)",
    )
    parser.add_argument("--solver", choices=SOLVERS, default="lm", help="nonlinear solver (default: lm)")
    parser.add_argument("--starts", type=int, default=4, metavar="N",
                        help="starting points of the multi-start search (default: 4)")
    parser.add_argument("--max-steps", type=int, default=200, metavar="N",
                        help="solver steps per start and per refinement (default: 200)")
    parser.add_argument("--align", choices=("none", "translation", "similarity", "affine"), default="none",
                        help="register the target onto the source inside the fit, for photographs "
                        "that are not pixel-aligned with their render (default: none; two to five times "
                        "the time; the warp goes into params.json)")
    parser.add_argument("--vignetting", action="store_true",
                        help="fit the camera's fall-off toward the corners as a gain field "
                        "1 + a1 rho^2 + a2 rho^4 (for photographs; the field goes into params.json)")
    parser.add_argument("--highlights", action="store_true",
                        help="refit with the specular highlights of a first fit's residual left out "
                        "(for photographs without cross-polarisation; their count goes into params.json)")
    parser.add_argument("--saturation", default="auto", metavar="LEVEL",
                        help="the targets' clipping level in their decoded units: masked pixels at or above "
                        "it are left out of the fit, and their count is a warning in params.json. 'auto' "
                        "(default): 1.0, the top code, when every target is an 8- or 16-bit file, and no "
                        "level for float targets (EXR); 'none': keep every pixel")
    parser.add_argument("--light-terms", default="none", metavar="TERMS",
                        help="fit light-aware terms on top of the blur (docs/model.md, section 8): "
                        "'shift' (light exits displaced away from the light; needs --light), "
                        "'grazing' (brighter or darker at grazing view; needs --normal), "
                        "'incidence' (brighter or darker where the key light grazes the skin or misses it; "
                        "needs --normal and --light), 'law' (the key light reflected by a scattering "
                        "medium's law instead of Lambert's, an albedo per source channel; needs --key, "
                        "--normal and --light), or a list such as 'shift,law'; "
                        "'shift=1.3' holds kappa at a value measured on a registered pair "
                        "(for --align), 'law=0.93/0.8/0.7' the albedos (default: none)")
    parser.add_argument("--canvas", default=None, metavar="HxW",
                        help="fit on a canvas of HxW pixels at least every pair's size (e.g. 256x256): pairs "
                        "of different sizes then share their compiled functions, in this process and in the "
                        "compilation cache, with the estimate of a fit at the pair's own size "
                        "(docs/model.md, section 7)")
    parser.add_argument("--light", action="append", default=[], metavar="FILE",
                        help="camera-space unit vectors towards the light, float EXR or NPY (H, W, 3), "
                        "on the source's grid (repeat per pair)")
    parser.add_argument("--normal", action="append", default=[], metavar="FILE",
                        help="camera-space unit normals (x right, y up, z to the camera), float EXR or "
                        "NPY (H, W, 3) (repeat per pair)")
    parser.add_argument("--key", action="append", default=[], metavar="FILE",
                        help="the source lit by the key light alone (the light --light points to), the "
                        "source's size and channels, read as the source is (repeat per pair; "
                        "'invsss scene' writes it as key.exr)")
    parser.add_argument(
        "--linear-codes",
        action="store_true",
        help="the source and target images' integer codes are linear values: do not "
        "decode 8-bit files as sRGB",
    )
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output directory (created if missing); a directory that "
                        "already holds a result is refused unless --overwrite is given")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the result already in DIR (its files only; other "
                        "files in DIR are kept)")
    _add_no_cache_argument(parser)
    parser.set_defaults(func=_run_fit)


def _canvas(text: str | None) -> tuple[int, int] | None:
    """``--canvas HxW``: two integers >= 1 (None when not given)."""
    if text is None:
        return None
    height, sep, width = text.lower().partition("x")
    try:
        return check_canvas((int(height), int(width)) if sep else None)
    except (ValueError, InvalidInputError):
        raise InvalidInputError(f"--canvas {text!r}: expected HxW, two integers >= 1 (e.g. 256x256)") from None


def _saturation_level(text: str, targets: list[str]) -> float | None:
    """``--saturation``: a number, 'none', or 'auto' (the targets' own clipping level)."""
    if text == "auto":
        return shared_clipping_level(targets)
    if text == "none":
        return None
    try:
        return float(text)
    except ValueError:
        raise InvalidInputError(f"--saturation {text!r}: expected auto, none or a number > 0") from None


def _parse_fix(items: list[str]) -> dict:
    """``["maxdd=0.05", "variances=0.5,2"]`` -> ``{"maxdd": 0.05, "variances": [0.5, 2.0]}``."""
    known = _FIX_SCALARS + _FIX_LISTS
    fixed: dict = {}
    for item in items:
        name, equals, text = (part.strip() for part in item.partition("="))
        if not equals or not name or not text:
            raise InvalidInputError(
                f"--fix {item!r}: expected NAME=VALUE, e.g. maxdd=0.05 or variances=0.5,2"
            )
        if name not in known:
            raise InvalidInputError(
                f"--fix {item!r}: unknown parameter {name!r}, expected one of {', '.join(known)}"
            )
        if name in fixed:
            raise InvalidInputError(f"--fix {item!r}: {name} is given more than once")
        try:
            numbers = [float(t) for t in text.split(",")]
        except ValueError:
            raise InvalidInputError(
                f"--fix {item!r}: expected "
                + ("a number" if name in _FIX_SCALARS else "comma-separated numbers")
            ) from None
        if name in _FIX_SCALARS:
            if len(numbers) != 1:
                raise InvalidInputError(f"--fix {item!r}: {name} takes a single number")
            fixed[name] = numbers[0]
        else:
            fixed[name] = numbers
    return fixed


def _check_pair_counts(args: argparse.Namespace) -> int:
    # issue 33: --depth and --mask may be left out (photo_pair.check_photo_arguments).
    counts = {flag: len(getattr(args, flag)) for flag in _PAIR_FLAGS if flag in ("source", "target") or getattr(args, flag)}
    if len(set(counts.values())) > 1:
        given = ", ".join(f"{n} --{flag}" for flag, n in counts.items())
        raise InvalidInputError(
            f"--source/--target/--depth/--mask: expected the same number of each "
            f"(one per pair), got {given}"
        )
    return counts["source"]


def _with_light_buffers(pairs, args):
    """The pairs with the --normal, --light and --key buffers attached (the vectors read
    as linear floats, the key as the source is)."""
    for flag in ("light", "normal", "key"):
        given = getattr(args, flag)
        if given and len(given) != len(pairs):
            raise InvalidInputError(f"--{flag}: expected one per pair ({len(pairs)}), got {len(given)}")
    out = []
    for k, pair in enumerate(pairs):
        normal = _read_light_buffer(args.normal[k], "normal", pair.mask.shape) if args.normal else None
        light = _read_light_buffer(args.light[k], "light", pair.mask.shape) if args.light else None
        key = _read_key_buffer(args.key[k], pair.source, args.linear_codes) if args.key else None
        out.append(ImagePair(pair.source, pair.target, pair.depth, pair.mask, normal=normal, light=light, key=key))
    return out


class _ProgressLine:
    """The fit's progress on stderr.

    On a terminal, one line rewritten in place (carriage return), at most ten
    times a second; otherwise (a pipe, a log file) a plain line every few seconds,
    so logs stay short. With ``compile_seconds`` (a callable: seconds spent
    compiling so far in this fit), the first solver step is preceded by one
    permanent line saying how long compilation took (or that the compiled code
    came from the cache).
    """

    def __init__(self, stream, compile_seconds=None):
        self._stream = stream
        self._compile_seconds = compile_seconds
        self._tty = bool(getattr(stream, "isatty", lambda: False)())
        self._interval = 0.1 if self._tty else 5.0
        self._last = -np.inf
        self._width = 0

    def show(self, text: str) -> None:
        if self._tty:
            self._stream.write("\r" + text.ljust(self._width))
            self._width = len(text)
        else:
            self._stream.write(text + "\n")
        self._stream.flush()

    def __call__(self, iteration: int, loss: float, stage: str | None = None) -> None:
        """``progress(iteration, loss)`` as the estimator calls it; ``stage`` (e.g.
        ``"start 2/4"``) is shown when given."""
        if self._compile_seconds is not None:
            # Everything the first step needs is compiled once it has run.
            self.close()
            seconds = self._compile_seconds()
            # A warm cache (invsss.runtime.executable_cache) leaves nothing to compile.
            self._stream.write(f"fit: compiling ... {seconds:.1f} s\n" if seconds >= 0.05
                               else "fit: compiled code loaded from the cache\n")
            self._compile_seconds = None
        now = time.monotonic()
        if now - self._last < self._interval:
            return
        self._last = now
        where = f"{stage}  " if stage else ""
        self.show(f"fit: {where}iter {iteration}  loss {loss:.3e}")

    def close(self) -> None:
        """Erase the in-place line, so what follows starts on a clean line."""
        if self._tty and self._width:
            self._stream.write("\r" + " " * self._width + "\r")
            self._stream.flush()
            self._width = 0


_COMPILING = {"spans": [], "listening": False}


def _compile_seconds() -> float:
    """Seconds of wall time during which this process was compiling (tracing,
    lowering, XLA; an executable loaded from the persistent cache counts its
    load), from ``jax.monitoring``; the listener is registered on the first call.

    A fit compiles its solver step on a second thread while the start scan's loss
    compiles, so the durations are not summed: each is an interval ending when
    its event arrives, and overlapping intervals count once.
    """
    if not _COMPILING["listening"]:
        from jax import monitoring

        def listen(event, duration, **_):
            if event.startswith("/jax/core/compile/"):
                end = time.monotonic()
                _COMPILING["spans"].append((end - duration, end))  # list.append is atomic

        monitoring.register_event_duration_secs_listener(listen)
        _COMPILING["listening"] = True
    return _covered_seconds(_COMPILING["spans"])


def _covered_seconds(spans) -> float:
    """The length of the union of ``(start, end)`` intervals.

    Examples
    --------
    >>> _covered_seconds([(0.0, 2.0), (1.0, 3.0), (5.0, 6.0)])
    4.0
    """
    total, reached = 0.0, -np.inf
    for start, end in sorted(spans):
        if end > reached:
            total += end - max(start, reached)
            reached = end
    return total


def _fit_file_names(count: int) -> list[str]:
    images = ["fit.exr"] if count == 1 else [f"fit_{k}.exr" for k in range(count)]
    return ["params.json", *images, "report.png"]


def _run_fit(args: argparse.Namespace, stop: StopSignals) -> int:
    for flag, value in (("--starts", args.starts), ("--max-steps", args.max_steps)):
        if value < 1:
            raise InvalidInputError(f"{flag}: expected an integer >= 1, got {value}")
    fix = _parse_fix(args.fix)
    canvas = _canvas(args.canvas)
    count = _check_pair_counts(args)
    # issue 33: check --depth/--distance/--mask before the output directory is touched.
    made_mask_names = photo_pair.check_photo_arguments(count, args.depth, args.distance, args.mask)
    names = _fit_file_names(count) + made_mask_names
    # Lock and check the output directory before reading anything, so a rerun
    # into a finished result or a busy directory is refused at once.
    with ResultDir(args.out, overwrite=args.overwrite, names=names) as out:
        inputs = photo_pair.photo_inputs(args.source, args.target, args.depth, args.distance, args.mask, fix=fix,
                                         depth_scale=args.depth_scale, linear_codes=args.linear_codes)
        pairs, fix = inputs.pairs, inputs.fix
        pairs = _with_light_buffers(pairs, args)
        # The report needs matplotlib (0.3-0.4 s to import, seconds while it builds
        # its font cache); import it beside the fit, whose solver steps leave the
        # interpreter free while XLA computes. Not a daemon: a process that ends
        # while a daemon thread runs compiled code (a fit interrupted at once) can
        # abort in C++ during shutdown (seen in CI: exit status -6 instead of 130).
        threading.Thread(
            target=importlib.import_module, args=("invsss.cli.report",), name="invsss-import-report"
        ).start()
        options = dict(
            model=args.model, profile=args.profile, fix=fix or None, gauge=args.gauge,
            solver=args.solver, n_starts=args.starts, max_steps=args.max_steps, align=args.align,
            vignetting=args.vignetting, highlights=args.highlights,
            saturation=_saturation_level(args.saturation, args.target), light_terms=args.light_terms,
            canvas=canvas,
        )
        compiled_before = _compile_seconds()
        progress = _ProgressLine(sys.stderr, lambda: _compile_seconds() - compiled_before)
        height, width, _ = pairs[0].source.shape
        progress.show(f"fit: {count} pair(s), {width}x{height}, model {args.model}: searching starting points")

        def stopping(signum):
            progress.close()
            print(
                f"invsss: {signal.Signals(signum).name}: stopping after the current solver step "
                "and saving the best estimate (send it again to quit without saving)",
                file=sys.stderr, flush=True,
            )

        # From here a first Ctrl-C or SIGTERM asks the fit to stop and the result
        # is still written; a second one quits at once.
        with stop.deferred(stopping):
            try:
                if count == 1:
                    pair = pairs[0]
                    result = fit_pair(
                        pair.source, pair.target, pair.depth, pair.mask, progress=progress, stop=stop,
                        light_buffers=pair.light_buffers, **options,
                    )
                else:
                    result = fit_pairs(pairs, progress=progress, stop=stop, **options)
            except FitInterrupted:
                progress.close()
                print("invsss: interrupted before the first solver step; nothing written", file=sys.stderr)
                return stop.exit_status or 130
            finally:
                progress.close()
            for message in result.warnings:
                print(f"invsss: warning: {message}", file=sys.stderr)
            written = _write_fit(out, names, result, pairs, inputs)
        if written is None:
            return 1
    if stop.exit_status is not None:
        print(
            f"invsss: interrupted after {result.iterations} iterations; wrote the best estimate "
            f"so far (\"interrupted\": true) to {', '.join(written)}",
            file=sys.stderr,
        )
        return stop.exit_status
    print(
        f"fit: loss {result.loss:.4g}  PSNR {result.psnr:.2f} dB  SSIM {result.ssim:.4f}  "
        f"{'converged' if result.converged else 'NOT converged'} ({result.iterations} iterations); "
        f"wrote {', '.join(written)}"
    )
    return 0


def _write_fit(out: ResultDir, names: list[str], result, pairs, inputs=None) -> list[str] | None:
    """Commit the fit's files to ``out``; on failure keep the estimate elsewhere and say where."""
    # matplotlib is only needed here; `invsss render` should not pay for importing it.
    from .report import plot_fit_report

    content = result.to_dict()
    if inputs is not None and inputs.record is not None:
        content["inputs"] = inputs.record  # issue 33: distance, made masks, held parameters
    writers = {"params.json": lambda path: write_params(path, content)}
    for name, image in zip(names[1:], result.fitted):
        writers[name] = lambda path, image=image: write_image(path, np.asarray(image, np.float32))
    writers["report.png"] = lambda path: plot_fit_report(result, pairs, path)
    for name, mask in ({} if inputs is None else inputs.made_masks).items():
        writers[name] = lambda path, mask=mask: write_image(path, mask)  # issue 33: DIR/mask_used.png
    info = {"command": "fit", "converged": bool(result.converged),
            "interrupted": bool(content.get("interrupted", False))}
    try:
        return out.commit(writers, info)
    except ResultWriteError as err:
        print(f"invsss: error: {err}; {_save_elsewhere(content)}", file=sys.stderr)
        return None


def _save_elsewhere(content: dict) -> str:
    """Keep a fit whose output directory failed: a file in the temp directory, else stdout."""
    stamp = time.strftime("%Y%m%d-%H%M%S")
    path = os.path.join(tempfile.gettempdir(), f"invsss-unsaved-{stamp}-{os.getpid()}.params.json")
    try:
        write_params(path, content)
        return f"the estimate was saved to {path}"
    except (OSError, InvalidInputError):
        sys.stdout.write(json.dumps(content, indent=2, default=_jsonable) + "\n")
        return "the estimate was printed on standard output"


def _jsonable(value):
    return value.tolist() if hasattr(value, "tolist") else str(value)


# ----------------------------------------------------------------- export


def _add_export_parser(subparsers) -> None:
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
    _add_model_arguments(parser)
    parser.add_argument("--taps", type=int, default=17,
                        help="separable only: kernel taps, odd (default: 17)")
    parser.add_argument("--strength", type=float, default=1.0,
                        help="separable only: blend of the kernel with the identity (default: 1)")
    parser.add_argument("--out", default=None, metavar="FILE",
                        help="output file (default: standard output)")
    parser.add_argument("--with-shader", action="store_true",
                        help="with --format hlsl and --out: also write the reference shader "
                        "(invsss_*.hlsl, docs/renderer.md) beside FILE, including it")
    parser.set_defaults(func=_run_export)


def _run_export(args: argparse.Namespace, stop: StopSignals) -> int:
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


# ---------------------------------------------------------------- scene


def _add_scene_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "scene",
        help="path-trace a source/target pair from a scene description (needs invsss[scenes])",
        description="Render CONFIG (a TOML scene description: object, camera, lights, "
        "occluders, medium) with Mitsuba 3 into DIR: source.exr (Lambertian), target.exr "
        "(scattering medium, reflection removed), depth.exr (eye z, mm), mask.png, "
        "normal.exr, coverage.exr and scene.json (everything needed to reproduce it, and "
        "the target's noise estimate).",
    )
    parser.add_argument("config", help="scene description (.toml)")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="output directory (created if missing); a directory that already "
                        "holds a result is refused unless --overwrite is given")
    parser.add_argument("--overwrite", action="store_true", help="replace the result already in DIR")
    parser.add_argument("--width", type=int, default=None, metavar="PX",
                        help="image width (default: the config's; alone, keeps the aspect ratio)")
    parser.add_argument("--height", type=int, default=None, metavar="PX",
                        help="image height (default: the config's; alone, keeps the aspect ratio)")
    parser.add_argument("--spp", type=int, default=None, metavar="N",
                        help="samples per pixel, even (default: the config's)")
    parser.add_argument("--seed", type=int, default=None, metavar="N", help="seed (default: the config's)")
    parser.add_argument("--warp", default=None, metavar="PARAMS_JSON",
                        help="a fit's params.json whose registration (fit --align translation or similarity) "
                        "moves the camera: the render lands on the photograph's pixel grid, and a fit with "
                        "--align again has only hundredths of a pixel left to resample (see docs/capture.md)")
    parser.add_argument("--source-only", action="store_true",
                        help="leave out the path-traced target: source, depth, mask and buffers only, for "
                        "fitting a photograph (the target is most of the render time)")
    parser.set_defaults(func=_run_scene)


def _warp_from_params(path: str):
    """The one warp in a fit's params.json (``alignment``), for ``scene --warp``."""
    from ..io import read_params

    _, extras = read_params(path)
    warps = extras.get("alignment") or []
    if len(warps) != 1:
        found = ("no alignment (the fit ran without --align)" if not warps
                 else f"{len(warps)} warps (a fit of several pairs)")
        raise InvalidInputError(f"--warp {path}: expected the params.json of a fit of one pair with --align, "
                                f"found {found}")
    return warps[0]


def _run_scene(args: argparse.Namespace, stop: StopSignals) -> int:
    # Imported here: the scene code needs Mitsuba, which the other commands do not.
    from ..scenes import load_config
    from ..scenes.render import SCENE_FILES, render_scene, scene_writers

    config = load_config(args.config)
    if args.warp is not None:
        # Before any --width/--height: the warp is in the pixels of the render it was fitted to.
        config = config.with_warp(_warp_from_params(args.warp))
    config = config.with_overrides(
        width=args.width, height=args.height, spp=args.spp, seed=args.seed,
        name=f"{args.config} with --width/--height/--spp/--seed",
    )
    with ResultDir(args.out, overwrite=args.overwrite, names=SCENE_FILES) as out:
        result = render_scene(config, progress=lambda text: print(text, file=sys.stderr, flush=True),
                              target=not args.source_only)
        try:
            written = out.commit(scene_writers(result), {"command": "scene"})
        except ResultWriteError as err:
            print(f"invsss: error: {err}", file=sys.stderr)
            return 1
    noise = result.info["noise"]
    ceiling = "no target" if noise is None else f"target noise ceiling {noise['noise_ceiling_db']:.1f} dB"
    print(
        f"scene: {config.camera.width}x{config.camera.height}, {config.spp} spp, "
        f"{result.info['render_seconds']['total']:.1f} s; {ceiling}; wrote {', '.join(written)}"
    )
    return 0


# ------------------------------------------------------------------ sweep


def _add_sweep_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep",
        help="run the trials of an experiment file (batch fits, render matrices, sweeps)",
        description="Expand EXPERIMENT.toml into trials and run those not yet done into DIR: "
        "DIR/results.sqlite (one row per trial) and DIR/trials/<id>/ (its files). Running the "
        "same command again resumes after a crash or Ctrl-C. Then see `invsss sweep-report DIR`.",
    )
    parser.add_argument("experiment", metavar="EXPERIMENT.toml", help="experiment file")
    parser.add_argument("--out", required=True, metavar="DIR", help="results folder (created if missing)")
    parser.add_argument("--executor", choices=("local", "dask"), default="local",
                        help="local: this process or a process pool (default); dask: a Dask cluster")
    parser.add_argument("--jobs", type=int, default=None, metavar="N",
                        help="local worker processes (default 1: this process), or the workers of "
                        "the Dask LocalCluster started without --scheduler (default 2)")
    parser.add_argument("--scheduler", default=None, metavar="ADDR",
                        help="address of a running Dask scheduler (tcp://host:8786)")
    parser.add_argument("--rebuild-store", action="store_true",
                        help="first make DIR/results.sqlite again from the trial folders DIR/trials/<id>/ "
                        "(after it was damaged; the old file is kept as results.sqlite.damaged-<time>), "
                        "then run the trials not done")
    parser.add_argument("--max-trials", type=int, default=None, metavar="N",
                        help="run an experiment of more trials than the limit "
                        "(default 100000; counted before they are expanded)")
    _add_no_cache_argument(parser)
    parser.set_defaults(func=_run_sweep)
    # `invsss sweep-report` is the sweep's other half: registered with it.
    _add_sweep_report_parser(subparsers)


def _run_sweep(args: argparse.Namespace, stop: StopSignals) -> int:
    from ..experiments import load, run
    from ..experiments.experiment import MAX_TRIALS

    limit = MAX_TRIALS if args.max_trials is None else args.max_trials
    if limit < 1:
        raise InvalidInputError(f"--max-trials: expected a whole number >= 1, got {limit}")
    experiment = load(args.experiment, max_trials=limit)

    def stopping(signum):
        print(f"invsss: {signal.Signals(signum).name}: no new trials will start; a fit running in "
              "this process stops at its next step, trials on workers finish; rerun to resume "
              "(send it again to quit now)", file=sys.stderr, flush=True)

    with stop.deferred(stopping):
        summary = run(experiment, args.out, executor=args.executor, jobs=args.jobs,
                      scheduler=args.scheduler, stop=stop,
                      rebuild_store=args.rebuild_store)
    _print_out(f"sweep: {summary.done} done, {summary.failed} failed, {summary.remaining} not run "
               f"({summary.ran} run now, {summary.seconds:.1f}s); report: invsss sweep-report {args.out}")
    if summary.interrupted:
        return stop.exit_status or 130
    # A script must see that some trials have no result; their errors are in the report.
    return 1 if summary.failed else 0


def _add_sweep_report_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sweep-report",
        help="tabulate and plot the results of a sweep",
        description="Print a table of the trials in DIR and write DIR/report/results.csv and "
        "PNG plots (metrics and fitted parameters against each axis; for a render sweep a "
        "contact sheet of the renders).",
    )
    parser.add_argument("out", metavar="DIR", help="a sweep's results folder")
    parser.add_argument("--no-plots", action="store_true", help="only the table and the CSV file")
    parser.add_argument("--parquet", action="store_true",
                        help="also write DIR/report/results.parquet (needs pandas and pyarrow)")
    parser.set_defaults(func=_run_sweep_report)


def _run_sweep_report(args: argparse.Namespace, stop: StopSignals) -> int:
    from ..experiments.report import write_report

    table, written = write_report(args.out, plots=not args.no_plots, parquet=args.parquet)
    _print_out(table)
    _print_out(f"wrote {', '.join(written)}")
    return 0


def _print_out(text: str) -> None:
    """Print ``text`` on stdout; a reader that went away (``| head``) is not an error."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        # Later writes, and Python's own flush at exit, go nowhere instead of failing.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


# ------------------------------------------------------------- profile


def _add_profile_parser(subparsers) -> None:
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
    parser.set_defaults(func=_run_profile)


def _run_profile(args: argparse.Namespace, stop: StopSignals) -> int:
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
    _add_fit_parser(subparsers)
    _add_export_parser(subparsers)
    _add_sweep_parser(subparsers)
    _add_scene_parser(subparsers)
    _add_profile_parser(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit code."""
    # Before JAX computes anything: XLA reads the flag when its backend starts.
    use_deterministic_scheduler()
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
        with warnings.catch_warnings(), StopSignals() as stop:
            warnings.showwarning = _show_warning
            _use_compile_cache(args)
            return args.func(args, stop)
    except InvalidInputError as err:
        print(f"invsss: error: {err}", file=sys.stderr)
        return 2
    except Interrupted as interrupt:
        # A signal outside the fit (reading, rendering): nothing to keep.
        print(f"invsss: interrupted ({interrupt}); nothing written", file=sys.stderr)
        return interrupt.exit_status


def _use_compile_cache(args: argparse.Namespace) -> None:
    """JAX's persistent compilation cache for the commands that compile (those with --no-cache)."""
    if not hasattr(args, "no_cache"):
        return
    if args.no_cache:
        # Through the environment, so that a sweep's worker processes see it too.
        os.environ["INVSSS_NO_CACHE"] = "1"
        return
    from ..runtime.compile_cache import enable_compile_cache

    enable_compile_cache()


def _show_warning(message, category, filename, lineno, file=None, line=None):
    # Library warnings reach a command-line user as one line, without a source location.
    print(f"invsss: warning: {message}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
