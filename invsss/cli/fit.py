"""``invsss fit``: estimate the parameters from image pairs and write a result directory.

The fit's options are :class:`~invsss.estimator.FitOptions` fields: each one's flag, default,
choices and help come from the field (:func:`add_fit_option_arguments`), and the
parsed command line becomes one ``FitOptions`` (:func:`fit_options_from`) handed
to :func:`~invsss.estimator.fit.run_fit`, the entry point the sweeps use too.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib
import json
import os
import signal
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Callable

import numpy as np

from ..estimator import FitInterrupted
from ..estimator.blur_width import blur_line
from ..estimator.fit import run_fit
from ..estimator.options import FitOptions
from ..forward.pair import ImagePair
from ..forward.params import DEPTH_UNITS
from ..io import photo_pair, resolved_saturation, write_image, write_params
from ..io.result_dir import ResultDir, ResultWriteError
from ..runtime.interrupts import StopSignals
from ..validation import InputNotice, InvalidInputError, one_line
from .arguments import add_no_cache_argument, read_key_buffer, read_light_buffer, read_thickness_buffer
from .progress import ProgressLine, compile_seconds, trial_seconds

#: The flags that give one file per pair.
_PAIR_FLAGS = ("source", "target", "depth", "mask")


def add_parser(subparsers) -> None:
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
    # Photographs without a 3D model (invsss.io.photo_pair, docs/capture.md): --distance
    # instead of --depth, and a mask made from the pair when --mask is left out.
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
    parser.add_argument(
        "--depth-scale",
        type=float,
        default=1.0,
        help="multiplies every stored depth (unit conversion, e.g. 1000 for metres to mm)",
    )
    parser.add_argument(
        "--depth-unit", choices=tuple(DEPTH_UNITS), default="mm",
        help="unit of the depth after --depth-scale (default: mm); params.json records it, and render and "
        "export convert from it",
    )
    add_fit_option_arguments(parser)
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
    parser.add_argument("--fill-light", action="append", default=[], metavar="FILE",
                        help="camera-space unit vectors towards the other lights (one direction standing "
                        "for every light but the key), float EXR or NPY (H, W, 3), for the 'fill' light "
                        "term (repeat per pair; 'invsss scene' writes the second light's as fill_light.exr)")
    parser.add_argument("--thickness", action="append", default=[], metavar="FILE",
                        help="mm the key light travels inside the skin to reach each pixel (0 where the "
                        "surface faces it), float EXR or NPY (H, W), for the 'transmission' light term "
                        "(repeat per pair; 'invsss scene' writes it as thickness.exr)")
    parser.add_argument("--key-irradiance", action="append", default=[], metavar="FILE",
                        help="the albedo times the key light's unshadowed irradiance on a surface facing "
                        "it, the source's size and channels, read as the source is, for the "
                        "'transmission' light term (repeat per pair; 'invsss scene' writes key_irradiance.exr)")
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
                        "files in DIR, and this fit's inputs among the result's files, are kept)")
    add_no_cache_argument(parser)
    parser.set_defaults(func=run)


def _fit_option_fields():
    """The :class:`FitOptions` fields the command line offers, with their flags."""
    for field in dataclasses.fields(FitOptions):
        flag = field.metadata["flag"]
        if flag is not None:
            yield field, flag or "--" + field.name.replace("_", "-")


def add_fit_option_arguments(parser: argparse.ArgumentParser) -> None:
    """One argument per :class:`FitOptions` field, with its flag, default, choices
    and help taken from the field (options.py is their one declaration)."""
    for field, flag in _fit_option_fields():
        meta = field.metadata
        keywords = dict(meta["argparse"])
        if meta["choices"] is not None:
            keywords["choices"] = tuple(meta["choices"]())
        default = meta["cli_default"]
        shown = "none" if default in (None, ()) and keywords.get("action") != "store_true" else default
        help_text = meta["help"]
        if keywords.get("action") not in ("store_true", "extend"):
            help_text += f" (default: {shown})"
        parser.add_argument(flag, dest=field.name, default=default, help=help_text, **keywords)


def fit_options_from(args: argparse.Namespace) -> FitOptions:
    """The :class:`FitOptions` of a parsed command line, checked before any file is
    read. ``--saturation auto`` stays ``"auto"`` here: :func:`run` resolves it from
    the targets' files (:func:`~invsss.io.resolved_saturation`) once the output
    directory is locked."""
    values = {}
    for field, flag in _fit_option_fields():
        value = getattr(args, field.name)
        parse = field.metadata["parse"]
        values[field.name] = value if parse is None else parse(value, flag)
    if values.get("profile") == "auto":
        # Two photographs at one distance resolve a blur of a pixel or two: one
        # Gaussian is what they determine (docs/capture.md); --profile asks for more.
        values["profile"] = "single" if getattr(args, "distance", None) else FitOptions.profile
    try:
        return FitOptions(**values)
    except InvalidInputError as err:
        # FitOptions names the field; the user typed its flag.
        flags = {field.name: flag for field, flag in _fit_option_fields()}
        raise (err.named(flags[err.field]) if err.field in flags else err) from None


def _check_pair_counts(args: argparse.Namespace) -> int:
    # --depth and --mask may be left out (photo_pair.check_photo_arguments says when).
    counts = {flag: len(getattr(args, flag)) for flag in _PAIR_FLAGS
              if flag in ("source", "target") or getattr(args, flag)}
    if len(set(counts.values())) > 1:
        given = ", ".join(f"{n} --{flag}" for flag, n in counts.items())
        raise InvalidInputError(
            f"--source/--target/--depth/--mask: expected the same number of each "
            f"(one per pair), got {given}"
        )
    return counts["source"]


def _with_light_buffers(pairs, args):
    """The pairs with the --normal, --light, --key, --fill-light, --thickness and
    --key-irradiance buffers attached (the vectors and the thickness read as linear floats,
    the key and the key irradiance as the source is)."""
    for flag in ("light", "normal", "key", "fill_light", "thickness", "key_irradiance"):
        given = getattr(args, flag)
        if given and len(given) != len(pairs):
            raise InvalidInputError(
                f"--{flag.replace('_', '-')}: expected one per pair ({len(pairs)}), got {len(given)}")
    out = []
    for k, pair in enumerate(pairs):
        normal = read_light_buffer(args.normal[k], "normal", pair.mask.shape) if args.normal else None
        light = read_light_buffer(args.light[k], "light", pair.mask.shape) if args.light else None
        key = read_key_buffer(args.key[k], pair.source, args.linear_codes) if args.key else None
        fill = (read_light_buffer(args.fill_light[k], "fill-light", pair.mask.shape) if args.fill_light
                else None)
        thickness = read_thickness_buffer(args.thickness[k], pair.mask.shape) if args.thickness else None
        irradiance = (read_key_buffer(args.key_irradiance[k], pair.source, args.linear_codes, "--key-irradiance")
                      if args.key_irradiance else None)
        out.append(ImagePair(pair.source, pair.target, pair.depth, pair.mask, normal=normal, light=light, key=key,
                             fill_light=fill, inputs_noted=pair.inputs_noted, thickness=thickness,
                             key_irradiance=irradiance))
    return out


def _fit_file_names(count: int) -> list[str]:
    images = ["fit.exr"] if count == 1 else [f"fit_{k}.exr" for k in range(count)]
    return ["params.json", *images, "report.png"]


def run(args: argparse.Namespace, stop: StopSignals) -> int:
    # The notices about the inputs go to the command line as they come, and into
    # params.json's warnings with the fit's own (as a sweep's trial records them).
    with _recording_notices() as notices:
        return _run(args, stop, notices)


def _run(args: argparse.Namespace, stop: StopSignals, notices: list[str]) -> int:
    options = fit_options_from(args)
    count = _check_pair_counts(args)
    # --depth/--distance/--mask checked before the output directory is touched.
    made_mask_names = photo_pair.check_photo_arguments(count, args.depth, args.distance, args.mask)
    names = _fit_file_names(count) + made_mask_names
    # Lock and check the output directory before reading anything, so a rerun
    # into a finished result or a busy directory is refused at once. The fit's
    # inputs are never lost: one that is a file of the result it replaces stays
    # (--mask DIR/mask_used.png --overwrite), one it would write over is refused,
    # and so is a file of the user's at a name it writes (docs/outputs.md).
    advice = dict.fromkeys(made_mask_names, "pass it with --mask to use it as the mask")
    with ResultDir(args.out, overwrite=args.overwrite, names=names, inputs=_input_files(args, options),
                   advice=advice) as out:
        inputs = photo_pair.photo_inputs(args.source, args.target, args.depth, args.distance, args.mask,
                                         fix=dict(options.fix),  # type: ignore[call-overload]  # a mapping by now
                                         depth_scale=args.depth_scale, linear_codes=args.linear_codes)
        pairs = inputs.pairs
        for path, pair in zip(args.depth, pairs):  # a distance was checked when it was read
            photo_pair.check_depth_level(pair.depth, pair.mask, DEPTH_UNITS[args.depth_unit], f"--depth {path}")
        if args.distance:
            # One distance holds correction and maxdd (inputs.held says at what).
            options = dataclasses.replace(options, fix=inputs.fix)
        pairs = _with_light_buffers(pairs, args)
        if options.saturation == "auto":  # the targets' own level: their files know it
            options = dataclasses.replace(options, saturation=resolved_saturation("auto", args.target))
        # The report needs matplotlib (0.3-0.4 s to import, seconds while it builds
        # its font cache); import it beside the fit, whose solver steps leave the
        # interpreter free while XLA computes. Not a daemon: a process that ends
        # while a daemon thread runs compiled code (a fit interrupted at once) can
        # abort in C++ during shutdown (seen in CI: exit status -6 instead of 130).
        threading.Thread(
            target=importlib.import_module, args=("invsss.cli.report",), name="invsss-import-report"
        ).start()
        compiled_before, tried_before = compile_seconds(), trial_seconds()
        progress = ProgressLine(sys.stderr, lambda: compile_seconds() - compiled_before,
                                lambda: trial_seconds() - tried_before)
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
                result = run_fit(pairs, count == 1, options, progress, stop)
            except InvalidInputError as err:
                raise _with_file_names(err, args, count) from None
            except FitInterrupted:
                progress.close()
                print("invsss: interrupted before the first solver step; nothing written", file=sys.stderr)
                return stop.exit_status or 130
            finally:
                progress.close()
            for message in result.warnings:
                print(f"invsss: warning: {message}", file=sys.stderr)
            written = _write_fit(out, names, result, pairs, inputs, "mm" if args.distance else args.depth_unit,
                                 notices)
        if written is None:
            return 1
    if stop.exit_status is not None:
        print(
            f"invsss: interrupted after {result.iterations} iterations; wrote the best estimate "
            f"so far (\"interrupted\": true) to {', '.join(written)}",
            file=sys.stderr,
        )
        return stop.exit_status
    _print_summary(result, written, "mm" if args.distance else args.depth_unit)
    return 0


def _print_summary(result, written: list[str], depth_unit: str) -> None:
    """The fit's two lines on stdout: loss, PSNR, convergence and files; the blur's width."""
    print(
        f"fit: loss {result.loss:.4g}  PSNR {result.psnr:.2f} dB  SSIM {result.ssim:.4f}  "
        f"{'converged' if result.converged else 'NOT converged'} ({result.iterations} iterations); "
        f"wrote {', '.join(written)}"
    )
    blur = blur_line(result.blur, depth_unit)
    if blur:
        print(f"fit: {blur}")


def _with_file_names(err: InvalidInputError, args: argparse.Namespace, count: int) -> InvalidInputError:
    """An estimator's error names a pair's role (``target``, ``pairs[1].mask``) in its
    ``field``; the user typed a file, so show its path: ``nir.png (target): ...``. A
    light-term buffer is shown as the flag that gives it (``--light: ...``)."""
    shown, paths = {}, {}
    for role in ("source", "target", "depth", "mask"):
        for i, path in enumerate(getattr(args, role, None) or ()):
            name = role if count == 1 else f"pairs[{i}].{role}"
            shown[name], paths[name] = f"{path} ({name})", path
    for buffer in ("normal", "light", "key", "fill_light", "thickness", "key_irradiance"):
        flag = "--" + buffer.replace("_", "-")
        shown["light_buffers." + buffer] = flag
        shown.update({f"pairs[{i}].{buffer}": flag + ("" if count == 1 else f" (pairs[{i}].{buffer})")
                      for i in range(count)})
    return err.named(shown[err.field], paths.get(err.field)) if err.field in shown else err


def _input_files(args: argparse.Namespace, options: FitOptions) -> list[tuple[str, str]]:
    """``(flag, path)`` of every file the fit reads, for :class:`ResultDir` to keep safe."""
    flags = (*_PAIR_FLAGS, "light", "normal", "key", "fill_light", "thickness", "key_irradiance")
    given = [(f"--{flag.replace('_', '-')}", path) for flag in flags for path in getattr(args, flag, None) or ()]
    if isinstance(options.profile, (str, os.PathLike)) and os.path.isfile(options.profile):
        given.append(("--profile", os.fspath(options.profile)))
    return given


@contextlib.contextmanager
def _recording_notices():
    """Within the block, each :class:`~invsss.validation.InputNotice` shown is also
    appended (as one line) to the list this yields."""
    notices: list[str] = []
    show = warnings.showwarning

    def recording(message, category, *rest, **keywords):
        if issubclass(category, InputNotice):
            notices.append(one_line(message))
        show(message, category, *rest, **keywords)

    with warnings.catch_warnings():
        warnings.showwarning = recording
        yield notices


def _write_fit(out: ResultDir, names: list[str], result, pairs, inputs=None,
               depth_unit: str = "mm", notices=()) -> list[str] | None:
    """Commit the fit's files to ``out``; on failure keep the estimate elsewhere and say where.

    ``notices`` (the input notices shown during the run) come first in params.json's
    ``warnings``, each once.
    """
    # matplotlib is only needed here; `invsss render` should not pay for importing it.
    from .report import plot_fit_report

    content = {**result.to_dict(), "depth_unit": depth_unit}
    content["warnings"] = list(dict.fromkeys([*notices, *content.get("warnings", ())]))
    if inputs is not None and inputs.record is not None:
        content["inputs"] = inputs.record  # a distance, made masks, held parameters
    writers: dict[str, Callable[..., object]] = {"params.json": lambda path: write_params(path, content)}
    for name, image in zip(names[1:], result.fitted):
        writers[name] = lambda path, image=image: write_image(path, np.asarray(image, np.float32))
    mask_notes = None if inputs is None else inputs.mask_notes  # a doubtful mask's line on the figure
    writers["report.png"] = lambda path: plot_fit_report(result, pairs, path, mask_notes=mask_notes,
                                                         depth_unit=depth_unit)
    for name, mask in ({} if inputs is None else inputs.made_masks).items():
        writers[name] = lambda path, mask=mask: write_image(path, mask)  # DIR/mask_used.png
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
