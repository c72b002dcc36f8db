"""Arguments and input buffers that several commands share."""

from __future__ import annotations

import argparse
import os

import numpy as np

from ..forward.passes import TAP_WEIGHTS
from ..forward.screen_space import MODELS
from ..io import image_extension, read_image
from ..io.params_file import warn_filled_for_model
from ..validation import InvalidInputError


def add_model_arguments(parser: argparse.ArgumentParser) -> None:
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


def check_output_path(path: str) -> None:
    """Fail before the work, not after it, when the output cannot be written."""
    image_extension(path, "output")
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise InvalidInputError(f"{path}: cannot write, directory {directory} does not exist", path=path)


def model_choice(args: argparse.Namespace, extras: dict) -> tuple[str, object]:
    """Model and tap weights: the command-line flag wins over the params file.

    Reading the file warned about the entries it filled from the fit's estimate only
    where the file's own model uses them (a ``burley`` fit's weights change nothing it
    renders); a ``--model`` that uses entries the file's model does not gets that
    warning here.
    """
    model = args.model or extras.get("model", MODELS[0])
    tap_weights = args.tap_weights or extras.get("tap_weights")
    warn_filled_for_model(args.params, extras, model)
    return model, tap_weights


def read_light_buffer(path, flag: str, shape):
    """A --light or --normal buffer, read as linear floats, of the image's size."""
    buffer = read_image(path, linear=True)
    if buffer.shape != (*shape, 3):
        raise InvalidInputError(
            f"{path}: expected a 3-channel image of the source's size {shape} for --{flag}, got shape {buffer.shape}",
            path=path,
        )
    return buffer


def read_key_buffer(path, source, linear_codes: bool, flag: str = "--key"):
    """A --key image (the source lit by the key light alone), read as the source is,
    of the source's size and channels."""
    source = np.asarray(source)
    # A grey source stored as RGB was read as one channel before a grey target: its key too.
    key = read_image(path, linear=linear_codes, grey=source.ndim == 2 or source.shape[-1] == 1)
    wanted = source.shape if source.ndim == 3 else (*source.shape, 1)
    key = key if key.ndim == 3 else key[..., None]
    if key.shape != wanted:
        raise InvalidInputError(
            f"{path}: expected an image of the source's size and channels {wanted} for {flag}, got shape {key.shape}",
            path=path,
        )
    return key


def read_thickness_buffer(path, shape):
    """A --thickness buffer (mm the key light travels inside the skin), read as linear
    floats, one channel of the image's size."""
    buffer = read_image(path, linear=True, grey=True)
    buffer = buffer[..., 0] if buffer.ndim == 3 and buffer.shape[-1] == 1 else buffer
    if buffer.shape != tuple(shape):
        raise InvalidInputError(
            f"{path}: expected a 1-channel image of the source's size {shape} for --thickness (mm), "
            f"got shape {buffer.shape}",
            path=path,
        )
    return buffer


def add_no_cache_argument(parser) -> None:
    """``--no-cache``, for the commands that compile (see :func:`_use_compile_cache`)."""
    parser.add_argument("--no-cache", action="store_true",
                        help="do not use the persistent compilation cache (also INVSSS_NO_CACHE=1); it "
                        "lives in ~/.cache/invsss/jax or $XDG_CACHE_HOME/invsss/jax, and "
                        "INVSSS_CACHE_DIR moves it")
