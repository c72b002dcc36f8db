"""Input validation at the public boundary.

Every check here raises :class:`InvalidInputError` with a single line that names
the input and says what was expected. The forward model and the estimator call
these before anything is traced, so a user never sees a traceback from inside
JAX for a bad input. Checks on *values* (NaN, sign, empty mask) only run on
concrete arrays: under ``jax.jit`` the inputs are tracers and the caller is
responsible (the file readers in :mod:`invsss.io` always validate).
"""

from __future__ import annotations

import jax
import numpy as np

__all__ = [
    "InputNotice",
    "InvalidInputError",
    "check_image",
    "check_depth",
    "check_mask",
    "check_same_size",
    "is_concrete",
]


class InvalidInputError(ValueError):
    """An input (array, file or config) is not what invsss expects."""


class InputNotice(UserWarning):
    """A note about how an input was interpreted (decoded as sRGB, alpha dropped, ...).

    Not an error: the input is used, but the user may have meant something else.
    Filter it with ``warnings.simplefilter("ignore", invsss.InputNotice)``.
    """


def is_concrete(x) -> bool:
    """True when ``x`` holds values (not a tracer inside ``jit``/``grad``/``vmap``)."""
    return not isinstance(x, jax.core.Tracer)


def _shape(x):
    return tuple(np.shape(x))


def check_image(image, name: str = "image", *, allow_batch: bool = False) -> None:
    """An image is (H, W) or (H, W, C) with C in {1, 3}, H, W >= 2, finite floats."""
    shape = _shape(image)
    core = shape[-3:] if (allow_batch and len(shape) > 3) else shape
    if len(core) == 2:
        h, w = core
    elif len(core) == 3:
        h, w, c = core
        if c not in (1, 3):
            raise InvalidInputError(
                f"{name}: expected 1 or 3 channels in the last axis, got shape {shape}"
            )
    else:
        raise InvalidInputError(f"{name}: expected shape (H, W) or (H, W, C), got {shape}")
    if h < 2 or w < 2:
        raise InvalidInputError(f"{name}: expected at least 2x2 pixels, got shape {shape}")
    # Tracers have a dtype; only plain sequences need converting to find one.
    dtype = np.dtype(image.dtype if hasattr(image, "dtype") else np.asarray(image).dtype)
    if not np.issubdtype(dtype, np.floating):
        raise InvalidInputError(
            f"{name}: expected linear floating-point values, got dtype {dtype} "
            "(decode 8/16-bit images with invsss.read_image)"
        )
    if is_concrete(image) and not bool(np.all(np.isfinite(np.asarray(image)))):
        raise InvalidInputError(f"{name}: contains NaN or infinite values")


def check_depth(depth, shape_hw: tuple[int, int], name: str = "depth") -> None:
    """Depth is (H, W), finite and strictly positive."""
    shape = _shape(depth)
    if shape != tuple(shape_hw):
        raise InvalidInputError(
            f"{name}: expected shape {tuple(shape_hw)} to match the image, got {shape}"
        )
    if is_concrete(depth):
        d = np.asarray(depth)
        if not np.all(np.isfinite(d)):
            raise InvalidInputError(f"{name}: contains NaN or infinite values")
        if not np.all(d > 0):
            raise InvalidInputError(
                f"{name}: expected depth > 0 everywhere, min is {float(d.min()):g}"
            )


def check_mask(mask, shape_hw: tuple[int, int], name: str = "mask") -> None:
    """Mask is (H, W) in [0, 1] with at least one non-zero pixel."""
    shape = _shape(mask)
    if shape != tuple(shape_hw):
        raise InvalidInputError(
            f"{name}: expected shape {tuple(shape_hw)} to match the image, got {shape}"
        )
    if is_concrete(mask):
        m = np.asarray(mask)
        if not np.all(np.isfinite(m)) or m.min() < 0 or m.max() > 1:
            raise InvalidInputError(f"{name}: expected values in [0, 1]")
        if not np.any(m > 0):
            raise InvalidInputError(f"{name}: is empty (no pixel > 0)")


def check_same_size(a_shape, b_shape, a_name: str, b_name: str) -> None:
    if tuple(a_shape[:2]) != tuple(b_shape[:2]):
        raise InvalidInputError(
            f"{b_name}: expected {a_shape[0]}x{a_shape[1]} pixels to match {a_name}, "
            f"got {b_shape[0]}x{b_shape[1]}"
        )
