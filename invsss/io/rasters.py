"""Image files as stored: which files invsss reads, and their pixel codes before decoding.

The lowest layer of the readers in :mod:`invsss.io` (:mod:`~invsss.io.images`,
:mod:`~invsss.io.depth`, :mod:`~invsss.io.masks`) and the writer
(:mod:`~invsss.io.writing`): the accepted file extensions, a path checked to be a
readable file, and :func:`read_raster`, which returns a file's codes (uint8,
uint16 or float) with the transfer function the file declares. How codes become
values is each reader's rule: colour is decoded (the table in
:mod:`invsss.io.images`), depth and masks are data and never colour-decoded.

OpenImageIO is imported the first time a file goes through it, so importing
:mod:`invsss` (or rendering arrays) does not pay for it.
"""

from __future__ import annotations

import os
import warnings
from typing import NamedTuple

import numpy as np

from ..validation import InputNotice, InvalidInputError, one_line

__all__ = [
    "IMAGE_EXTENSIONS",
    "Raster",
    "checked_path",
    "code_bits",
    "image_extension",
    "open_input",
    "openimageio",
    "read_raster",
]

#: File extensions the readers and :func:`~invsss.io.writing.write_image` accept (case-insensitive).
IMAGE_EXTENSIONS = (".exr", ".png", ".tif", ".tiff", ".jpg", ".jpeg", ".npy")


def openimageio():
    """The OpenImageIO module.

    Imported on first use: OpenImageIO is a large extension module that
    rendering arrays never needs.
    """
    import OpenImageIO

    return OpenImageIO


def image_extension(path, kind: str = "image") -> str:
    """The lower-case extension of ``path`` if invsss reads and writes it, else a one-line error."""
    name = os.fspath(path)
    ext = os.path.splitext(name)[1].lower()
    if ext not in IMAGE_EXTENSIONS:
        raise InvalidInputError(
            f"{name}: unsupported {kind} file extension {ext or '(none)'!r}, "
            f"expected one of {', '.join(IMAGE_EXTENSIONS)}",
            field=name,
        )
    return ext


def checked_path(path, kind: str) -> tuple[str, str]:
    """The path as a string and its lower-case extension, or a one-line error."""
    name = os.fspath(path)
    ext = image_extension(name, kind)
    if not os.path.exists(name):
        raise InvalidInputError(f"{name}: {kind} file not found", field=name)
    if os.path.isdir(name):
        article = "an" if kind[0] in "aeiou" else "a"
        raise InvalidInputError(f"{name}: is a directory, expected {article} {kind} file", field=name)
    return name, ext


def _declared_encoding(spec) -> str | float | None:
    """The file's declared transfer function: "srgb", a gamma (1.0 = linear), or None."""
    oiio = openimageio()
    name = spec.get_string_attribute("oiio:ColorSpace")
    if name:
        if oiio.equivalent_colorspace(name, "srgb_rec709_scene"):
            return "srgb"
        # A fresh config each time: one cached for the process outlives the bindings
        # at exit (nanobind reports a leak); files are read rarely, this is cheap.
        gamma = oiio.ColorConfig().get_transfer_function_gamma(name)
        if gamma > 0:
            return float(gamma)
    gamma = spec.get_float_attribute("oiio:Gamma", 0.0)
    return float(gamma) if gamma > 0 else None


class Raster(NamedTuple):
    """Pixels as stored: ``codes`` (H, W, C) uint8, uint16 or float (images: alpha removed)."""

    codes: np.ndarray
    encoding: str | float | None  # see _declared_encoding
    file_format: str  # OpenImageIO's format name ("png", "openexr", ...) or "npy"
    # Relative precision of stored floats (half: 2**-10), read as float32: codes
    # that differ by less were one value in the file. None for integer codes.
    float_eps: float | None = None


def open_input(name: str, kind: str):
    """An OpenImageIO ImageInput on ``name`` (close it), or a one-line error."""
    oiio = openimageio()
    image_input = oiio.ImageInput.open(name)
    if image_input is None:
        raise InvalidInputError(
            f"{name}: cannot read {kind} file ({one_line(oiio.geterror()) or 'unknown error'})",
            field=name,
        )
    return image_input


def read_raster(path, kind: str) -> tuple[str, Raster]:
    name, ext = checked_path(path, kind)
    if ext == ".npy":
        try:
            array = np.load(name, allow_pickle=False)
        except Exception as err:  # NumPy raises several types for a bad file
            raise InvalidInputError(f"{name}: cannot read NPY file ({one_line(err)})", field=name) from None
        if array.ndim == 2:
            array = array[..., None]
        if array.ndim != 3 or array.dtype.kind not in "biuf":
            raise InvalidInputError(
                f"{name}: expected a numeric (H, W) or (H, W, C) array, "
                f"got {array.dtype} of shape {array.shape}",
                field=name,
            )
        eps = float(np.finfo(array.dtype).eps) if array.dtype.kind == "f" else None
        return name, Raster(array, None, "npy", eps)

    oiio = openimageio()
    image_input = open_input(name, kind)
    try:
        spec = image_input.spec()
        basetype = spec.format.basetype
        read_as = {oiio.UINT8: "uint8", oiio.UINT16: "uint16"}.get(basetype, "float")
        if read_as == "float" and basetype not in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
            raise InvalidInputError(
                f"{name}: unsupported pixel type {spec.format}, "
                "expected 8- or 16-bit unsigned integers or floats",
                field=name,
            )
        codes = image_input.read_image(format=read_as)
        if codes is None or image_input.has_error:
            raise InvalidInputError(
                f"{name}: cannot read {kind} file, it may be truncated or corrupt "
                f"({one_line(image_input.geterror()) or 'no pixels'})",
                field=name,
            )
        file_format = image_input.format_name()
    finally:
        image_input.close()
    codes = np.asarray(codes).reshape(spec.height, spec.width, spec.nchannels)
    if kind == "image":
        # Alpha and a render's depth channel (Z) are not colour.
        extra = [c for c in (spec.alpha_channel, spec.z_channel) if c >= 0]
        if spec.alpha_channel >= 0:
            _note_dropped_alpha(name, codes[..., spec.alpha_channel])
        codes = np.delete(codes, extra, axis=2)
    elif kind == "depth" and spec.z_channel >= 0:
        # A render with a named depth channel: that is the depth, not channel 0.
        codes = codes[..., spec.z_channel : spec.z_channel + 1]
    # Doubles arrive as float32 (read_as "float"): theirs is float32's precision.
    eps = {oiio.HALF: 2.0**-10, oiio.FLOAT: 2.0**-23, oiio.DOUBLE: 2.0**-23}.get(basetype)
    return name, Raster(codes, _declared_encoding(spec), file_format, eps)


def code_bits(codes: np.ndarray) -> int | None:
    """8 or 16 for unsigned integer codes, None for floats."""
    if codes.dtype == np.uint8 or codes.dtype == np.bool_:
        return 8
    if codes.dtype.kind in "iu":
        return 8 * codes.dtype.itemsize
    return None


def _note_dropped_alpha(name: str, alpha: np.ndarray) -> None:
    """Say so when a transparent or translucent alpha is dropped: its colour is used as stored."""
    bits = code_bits(alpha)
    opaque = 1.0 if bits is None else float(2**bits - 1)
    see_through = int(np.count_nonzero(alpha < opaque))
    if see_through:
        warnings.warn(
            f"{name}: alpha channel dropped, though {see_through} pixel(s) are not opaque; "
            "their colour is used as stored (put the skin region in the mask instead)",
            InputNotice,
            stacklevel=4,
        )
