"""Reading and writing images, depth and masks.

Pixels go through OpenImageIO (EXR, PNG, TIFF, JPEG) or NumPy (``.npy``). The
model works on *linear* values (docs/model.md, section 1), so every reader returns
linear float32 arrays and every writer encodes them for the file format. How an
integer file is decoded:

============  ===========================================  ================
stored as     declared colour space (``oiio:ColorSpace``)  decoded with
============  ===========================================  ================
float / half  anything                                     nothing (linear)
integer       linear (e.g. a PNG ``gAMA`` of 1.0)          ``c``
integer       a pure gamma ``g`` (a PNG ``gAMA`` chunk)    ``c ** g``
8-bit         sRGB, or nothing                             the sRGB EOTF
16-bit        sRGB, declared by a TIFF                     the sRGB EOTF
16-bit        nothing, or the sRGB label of a PNG          ``c`` (linear)
============  ===========================================  ================

with ``c`` the code value divided by its maximum (255 or 65535). 8-bit images
are display-referred by convention (cameras, the web). 16-bit files are taken as
linear, the usual convention for 16-bit renders, depth maps and raw-derived
photographs; a PNG's sRGB label is ignored for them because OpenImageIO labels
(and writes) every PNG as sRGB whether or not its pixels are encoded, so the
label says nothing. Give a 16-bit PNG an explicit ``gAMA`` chunk if it really
is gamma-encoded, or convert it to EXR.

Depth and masks are data, not colour: their integer codes are never
colour-decoded. Every failure raises :class:`~invsss.validation.InvalidInputError`
with one line that names the file and what was expected. Writers are atomic:
they write a temporary file next to the target and ``os.replace`` it, so an
interrupted run never leaves half a file behind.

OpenImageIO is imported the first time a file goes through it, so importing
:mod:`invsss` (or rendering arrays) does not pay for it.
"""

from __future__ import annotations

import contextlib
import math
import os
import secrets
import warnings
from typing import NamedTuple

import numpy as np

from ..forward.pair import ImagePair, fill_background_depth
from ..validation import InputNotice, InvalidInputError, check_image, check_pair, depth_is_valid
from .colour import linear_to_srgb, srgb_to_linear

__all__ = [
    "IMAGE_EXTENSIONS",
    "clipping_level",
    "image_extension",
    "shared_clipping_level",
    "ImagePair",
    "load_pair",
    "read_depth",
    "read_image",
    "read_mask",
    "write_image",
    "write_text_atomic",
]

#: File extensions the readers and :func:`write_image` accept (case-insensitive).
IMAGE_EXTENSIONS = (".exr", ".png", ".tif", ".tiff", ".jpg", ".jpeg", ".npy")

# Bits written for each extension when write_image is not told (EXR/TIFF keep
# full float precision, PNG/JPEG are 8-bit sRGB like any viewer expects).
_DEFAULT_BITS = {".exr": 32, ".png": 8, ".tif": 32, ".tiff": 32, ".jpg": 8, ".jpeg": 8, ".npy": 32}
_ALLOWED_BITS = {
    ".exr": (16, 32),
    ".png": (8, 16),
    ".tif": (8, 16, 32),
    ".tiff": (8, 16, 32),
    ".jpg": (8,),
    ".jpeg": (8,),
    ".npy": (32,),
}
_DEPTH_FORMATS = "expected float EXR, NPY, or 16-bit PNG with a scale"


def _oiio():
    # Imported on first use: OpenImageIO is a large extension module that
    # rendering arrays never needs.
    import OpenImageIO

    return OpenImageIO


# ----------------------------------------------------------------- reading pixels


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def image_extension(path, kind: str = "image") -> str:
    """The lower-case extension of ``path`` if invsss reads and writes it, else a one-line error."""
    name = os.fspath(path)
    ext = os.path.splitext(name)[1].lower()
    if ext not in IMAGE_EXTENSIONS:
        raise InvalidInputError(
            f"{name}: unsupported {kind} file extension {ext or '(none)'!r}, "
            f"expected one of {', '.join(IMAGE_EXTENSIONS)}"
        )
    return ext


def _checked_path(path, kind: str) -> tuple[str, str]:
    """The path as a string and its lower-case extension, or a one-line error."""
    name = os.fspath(path)
    ext = image_extension(name, kind)
    if not os.path.exists(name):
        raise InvalidInputError(f"{name}: {kind} file not found")
    if os.path.isdir(name):
        article = "an" if kind[0] in "aeiou" else "a"
        raise InvalidInputError(f"{name}: is a directory, expected {article} {kind} file")
    return name, ext


def _declared_encoding(spec) -> str | float | None:
    """The file's declared transfer function: "srgb", a gamma (1.0 = linear), or None."""
    oiio = _oiio()
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


class _Raster(NamedTuple):
    """Pixels as stored: ``codes`` (H, W, C) uint8, uint16 or float (images: alpha removed)."""

    codes: np.ndarray
    encoding: str | float | None  # see _declared_encoding
    file_format: str  # OpenImageIO's format name ("png", "openexr", ...) or "npy"
    # Relative precision of stored floats (half: 2**-10), read as float32: codes
    # that differ by less were one value in the file. None for integer codes.
    float_eps: float | None = None


def _open_input(name: str, kind: str):
    """An OpenImageIO ImageInput on ``name`` (close it), or a one-line error."""
    oiio = _oiio()
    image_input = oiio.ImageInput.open(name)
    if image_input is None:
        raise InvalidInputError(
            f"{name}: cannot read {kind} file ({_one_line(oiio.geterror()) or 'unknown error'})"
        )
    return image_input


def _read_raster(path, kind: str) -> tuple[str, _Raster]:
    name, ext = _checked_path(path, kind)
    if ext == ".npy":
        try:
            array = np.load(name, allow_pickle=False)
        except Exception as err:  # NumPy raises several types for a bad file
            raise InvalidInputError(f"{name}: cannot read NPY file ({_one_line(err)})") from None
        if array.ndim == 2:
            array = array[..., None]
        if array.ndim != 3 or array.dtype.kind not in "biuf":
            raise InvalidInputError(
                f"{name}: expected a numeric (H, W) or (H, W, C) array, "
                f"got {array.dtype} of shape {array.shape}"
            )
        eps = float(np.finfo(array.dtype).eps) if array.dtype.kind == "f" else None
        return name, _Raster(array, None, "npy", eps)

    oiio = _oiio()
    image_input = _open_input(name, kind)
    try:
        spec = image_input.spec()
        basetype = spec.format.basetype
        read_as = {oiio.UINT8: "uint8", oiio.UINT16: "uint16"}.get(basetype, "float")
        if read_as == "float" and basetype not in (oiio.HALF, oiio.FLOAT, oiio.DOUBLE):
            raise InvalidInputError(
                f"{name}: unsupported pixel type {spec.format}, "
                "expected 8- or 16-bit unsigned integers or floats"
            )
        codes = image_input.read_image(format=read_as)
        if codes is None or image_input.has_error:
            raise InvalidInputError(
                f"{name}: cannot read {kind} file, it may be truncated or corrupt "
                f"({_one_line(image_input.geterror()) or 'no pixels'})"
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
    return name, _Raster(codes, _declared_encoding(spec), file_format, eps)


def _bits(codes: np.ndarray) -> int | None:
    """8 or 16 for unsigned integer codes, None for floats."""
    if codes.dtype == np.uint8 or codes.dtype == np.bool_:
        return 8
    if codes.dtype.kind in "iu":
        return 8 * codes.dtype.itemsize
    return None


def _note_dropped_alpha(name: str, alpha: np.ndarray) -> None:
    """Say so when a transparent or translucent alpha is dropped: its colour is used as stored."""
    opaque = 1.0 if _bits(alpha) is None else float(2 ** _bits(alpha) - 1)
    see_through = int(np.count_nonzero(alpha < opaque))
    if see_through:
        warnings.warn(
            f"{name}: alpha channel dropped, though {see_through} pixel(s) are not opaque; "
            "their colour is used as stored (put the skin region in the mask instead)",
            InputNotice,
            stacklevel=4,
        )


def _decode_colour(raster: _Raster, linear: bool = False) -> tuple[np.ndarray, str | float | None]:
    """Linear float values from stored codes, by the rule in the module docstring.

    Returns the values and the transfer function undone: "srgb", a gamma, or
    None for float data. ``linear=True`` takes integer codes as linear values.
    """
    codes = raster.codes
    bits = _bits(codes)
    if bits is None:
        return codes.astype(np.float32), None
    c = codes.astype(np.float64) / float(2**bits - 1)
    encoding = raster.encoding
    if encoding == "srgb" and bits > 8 and raster.file_format == "png":
        encoding = None  # OpenImageIO's default label for every PNG: no information
    if encoding is None:
        encoding = "srgb" if bits == 8 else 1.0
    if linear:
        encoding = 1.0
    decoded = srgb_to_linear(c) if encoding == "srgb" else c**encoding
    return decoded.astype(np.float32), encoding


def read_image(path, *, linear: bool = False, grey: bool = False) -> np.ndarray:
    """Read a colour or grey image as linear float32.

    Parameters
    ----------
    path : str or os.PathLike
        An EXR, PNG (8/16-bit), TIFF, JPEG or float ``.npy`` file.
    linear : bool
        The file's integer codes already hold linear values (e.g. an 8-bit PNG
        of raw sensor data): divide them by their maximum and nothing else,
        whatever the file declares. Float files are unaffected.
    grey : bool
        Read a grey stored as three identical channels (to within the file's
        precision, as :func:`load_pair` judges it) as one channel, with a notice:
        for an image that must match a one-channel source.

    Returns
    -------
    numpy.ndarray, shape (H, W, C), float32
        ``C`` is 1 or 3 (alpha and a ``Z`` depth channel are dropped). Integer files are decoded
        to linear [0, 1]: 8-bit as sRGB, 16-bit as linear, unless the file
        declares otherwise (table in :mod:`invsss.io.images`). Float files are returned
        as stored.

    Raises
    ------
    InvalidInputError
        Missing, unreadable or corrupt file, unsupported extension, a channel
        count other than 1 or 3, fewer than 2x2 pixels, NaN or infinite values.

    Warns
    -----
    InputNotice
        Integer codes were decoded as sRGB (say ``linear=True`` if they are
        linear), an alpha channel with non-opaque pixels was dropped, or
        (``grey=True``) three identical channels were read as one.

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "grey.png")
    >>> invsss.write_image(path, np.full((4, 4), 0.5, np.float32))
    >>> image = invsss.read_image(path)
    >>> image.shape, round(float(image[0, 0, 0]), 2)
    ((4, 4, 1), 0.5)
    """
    image, is_grey = _read_colour(path, linear)
    if grey and is_grey:
        _note_grey(os.fspath(path), "")
        return _one_channel(image)
    return image


def _read_colour(path, linear: bool) -> tuple[np.ndarray, bool]:
    """:func:`read_image`'s image, and whether it is a grey stored as three channels."""
    name, raster = _read_raster(path, "image")
    if raster.file_format == "npy" and raster.codes.dtype.kind != "f":
        raise InvalidInputError(
            f"{name}: expected a float NPY array of linear values, got {raster.codes.dtype} "
            "(save integer-coded images as PNG or TIFF so their encoding is known)"
        )
    image, encoding = _decode_colour(raster, linear)
    if encoding == "srgb":
        warnings.warn(
            f"{name}: {_bits(raster.codes)}-bit codes decoded as sRGB to linear values "
            "(if they are linear already, use linear=True / --linear-codes)",
            InputNotice,
            stacklevel=3,
        )
    if image.shape[2] not in (1, 3):
        raise InvalidInputError(
            f"{name}: expected 1 or 3 colour channels (plus optional alpha), got {image.shape[2]}"
        )
    check_image(image, name)
    return np.ascontiguousarray(image), _is_grey_rgb(raster)


#: How far apart, in 8-bit codes, a JPEG's channels may lie and still be one grey.
#: A grey pixel has chroma Cb = Cr = 128 exactly, a flat plane that neither chroma
#: subsampling nor quantisation changes: libjpeg (through OpenImageIO) decoded
#: grey JPEGs to identical channels at 4:4:4, 4:2:2 and 4:2:0, quality 50-100.
#: One code allows for decoders that round each channel on its own; a tint of
#: two codes survives JPEG as two codes, so it is still read as colour.
JPEG_GREY_CODES = 1


def _is_grey_rgb(raster: _Raster) -> bool:
    """Whether a three-channel image's channels are identical to within the file's precision.

    Compared on the stored codes: integer codes exactly (a JPEG's to within
    :data:`JPEG_GREY_CODES`), floats to within the relative precision of their
    stored type (a grey written through a colour matrix may differ in the last bit).
    """
    codes = raster.codes
    if codes.ndim != 3 or codes.shape[2] != 3:
        return False
    first, others = codes[..., :1], codes[..., 1:]
    if raster.float_eps is None:
        allowed = JPEG_GREY_CODES if raster.file_format == "jpeg" else 0
        return bool(np.all(np.abs(others.astype(np.int32) - first.astype(np.int32)) <= allowed))
    first, others = first.astype(np.float64), others.astype(np.float64)
    scale = np.maximum(np.abs(first), np.abs(others))
    return bool(np.all(np.abs(others - first) <= raster.float_eps * scale))


def _one_channel(image: np.ndarray) -> np.ndarray:
    """The mean of ``image``'s channels as one channel (exactly the value where they agree)."""
    return image.astype(np.float64).mean(axis=2, keepdims=True).astype(np.float32)


def _note_grey(name: str, what: str) -> None:
    warnings.warn(
        f"{name}: its three channels are identical (a grey image stored as RGB); read as one "
        f"grey channel{what}",
        InputNotice,
        stacklevel=3,
    )


def clipping_level(path) -> float | None:
    """The value a clipped pixel of an image file reads as, or None if the file cannot clip.

    An integer-coded file (8- or 16-bit) stores nothing brighter than its top code, so a
    pixel there may have been brighter still: it is clipped. Every decoding of
    :func:`read_image` maps the top code to 1.0, so that is the level; float files
    (EXR, float TIFF or ``.npy``) hold any value and give None. Only the header is read.

    Parameters
    ----------
    path : str or os.PathLike
        An image file, as for :func:`read_image`.

    Returns
    -------
    float or None
        1.0 for integer-coded files, None for float ones: what to pass as
        ``saturation`` to :func:`~invsss.fit_pair` for a target read from ``path``.

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> folder = tempfile.mkdtemp()
    >>> invsss.write_image(os.path.join(folder, "photo.png"), np.full((4, 4), 0.5, np.float32))
    >>> invsss.write_image(os.path.join(folder, "render.exr"), np.full((4, 4), 0.5, np.float32))
    >>> invsss.clipping_level(os.path.join(folder, "photo.png")), invsss.clipping_level(os.path.join(folder, "render.exr"))
    (1.0, None)
    """
    name, ext = _checked_path(path, "image")
    if ext == ".npy":
        # read_image accepts float arrays only: nothing to clip.
        return None
    oiio = _oiio()
    image_input = _open_input(name, "image")
    try:
        basetype = image_input.spec().format.basetype
    finally:
        image_input.close()
    return 1.0 if basetype in (oiio.UINT8, oiio.UINT16) else None


def shared_clipping_level(paths) -> float | None:
    """One clipping level for the targets ``paths`` (``saturation="auto"``), or None.

    The level of :func:`clipping_level` when every file is integer-coded. If any is
    a float file, no level: one level serves every pair, and a float target may
    hold values above 1 legitimately; a notice says so when some files are
    integer-coded all the same.

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> folder = tempfile.mkdtemp()
    >>> paths = [os.path.join(folder, name) for name in ("a.png", "b.png")]
    >>> for path in paths:
    ...     invsss.write_image(path, np.full((4, 4), 0.5, np.float32))
    >>> invsss.io.shared_clipping_level(paths)
    1.0
    """
    levels = {os.fspath(path): clipping_level(path) for path in paths}
    floats = [name for name, level in levels.items() if level is None]
    if not floats:
        return min(levels.values()) if levels else None
    if len(floats) < len(levels):
        warnings.warn(
            f"saturation auto: no clipping level set, as a float target ({', '.join(floats)}) may hold values "
            "above 1; give the level to leave the integer-coded targets' clipped pixels out",
            InputNotice,
            stacklevel=2,
        )
    return None


def read_depth(path, scale: float = 1.0) -> np.ndarray:
    """Read linear eye-space depth as float32 (H, W), multiplied by ``scale``.

    Parameters
    ----------
    path : str or os.PathLike
        A float EXR or TIFF (the ``Z`` channel if the file names one, else the
        first channel), a ``.npy`` array, or a 16-bit PNG/TIFF whose integer
        codes (0..65535, not normalised) times ``scale`` are the depth, as depth
        cameras store millimetres or fractions of a metre.
    scale : float
        Multiplies the stored values; use it to convert units (millimetres are
        recommended, docs/model.md, section 1).

    Returns
    -------
    numpy.ndarray, shape (H, W), float32
        As stored: where nothing was seen, renderers write 0 or +inf and depth
        cameras 0; those values are kept. Whether the skin pixels have usable
        depth is checked against the mask (:func:`load_pair`,
        :func:`invsss.validation.check_depth`).

    Raises
    ------
    InvalidInputError
        Missing or corrupt file, 8-bit data (too coarse for depth), no pixel with
        finite depth > 0, a bad ``scale``.

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "depth.npy")
    >>> np.save(path, np.full((4, 4), 0.5))
    >>> float(invsss.read_depth(path, scale=1000.0)[0, 0])
    500.0
    """
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise InvalidInputError(f"depth scale: expected a finite number > 0, got {scale!r}")
    name, raster = _read_raster(path, "depth")
    codes = raster.codes[..., 0]
    bits = _bits(codes)
    if bits == 8:
        raise InvalidInputError(f"{name}: 8-bit depth is too coarse, {_DEPTH_FORMATS}")
    if bits is not None and raster.file_format != "npy" and codes.dtype != np.uint16:
        raise InvalidInputError(f"{name}: unsupported depth type {codes.dtype}, {_DEPTH_FORMATS}")
    depth = (codes.astype(np.float64) * scale).astype(np.float32)
    if depth.shape[0] < 2 or depth.shape[1] < 2:
        raise InvalidInputError(f"{name}: expected at least 2x2 pixels, got {depth.shape}")
    if not depth_is_valid(depth).any():
        raise InvalidInputError(f"{name}: expected finite depth > 0 on the skin, no pixel has it")
    return depth


def read_mask(path) -> np.ndarray:
    """Read a skin mask as float32 (H, W) in [0, 1] from its first channel.

    Integer image codes are divided by their maximum (255 or 65535) with no
    colour decoding: a mask is data. Codes whose largest is 1 (a boolean mask
    saved with ``astype(uint8)``) are read as 0 and 1. Float files and ``.npy``
    arrays (float, bool or integer) must already hold values in [0, 1].

    Raises
    ------
    InvalidInputError
        Missing or corrupt file, values outside [0, 1] or NaN, an empty mask
        (no pixel > 0).

    Warns
    -----
    InputNotice
        Integer codes 0 and 1 were read as 0 and 1; no pixel reaches
        :data:`MASK_FAINT`; or more than :data:`MASK_SOFT_SHARE` of the non-zero
        pixels lie between 0 and 1.

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "mask.npy")
    >>> np.save(path, np.eye(4, dtype=bool))
    >>> float(invsss.read_mask(path).sum())
    4.0
    """
    name, raster = _read_raster(path, "mask")
    codes = raster.codes[..., 0]
    bits = _bits(codes)
    if bits is not None and raster.file_format != "npy":
        mask = codes.astype(np.float64) / _mask_top_code(codes, bits, name)
    else:
        mask = codes.astype(np.float64)
    mask = mask.astype(np.float32)
    if mask.shape[0] < 2 or mask.shape[1] < 2:
        raise InvalidInputError(f"{name}: expected at least 2x2 pixels, got {mask.shape}")
    if not np.all(np.isfinite(mask)) or mask.min() < 0 or mask.max() > 1:
        raise InvalidInputError(
            f"{name}: expected mask values in [0, 1], got range "
            f"[{float(np.nanmin(mask)):g}, {float(np.nanmax(mask)):g}]"
            + (" with NaN" if np.any(np.isnan(mask)) else "")
        )
    if not np.any(mask > 0):
        raise InvalidInputError(f"{name}: mask is empty (no pixel > 0), expected some skin")
    _note_mask_levels(mask, name)
    return mask


#: A mask none of whose pixels reaches this is not a skin mask at full strength.
MASK_FAINT = 0.5
#: A mask with more than this share of its non-zero pixels strictly between
#: 0 and 1 (give or take one 8-bit code) is more than a binary mask with a soft rim.
MASK_SOFT_SHARE = 0.5


def _mask_top_code(codes: np.ndarray, bits: int, name: str) -> float:
    """The code a mask file's 1.0 is stored as: the type's top code, or 1 for 0/1 codes."""
    top = float(2**bits - 1)
    if int(codes.max()) == 1:
        # numpy's astype(uint8) of a boolean mask: read as 0.0039 it left the
        # image all but unblurred and moved fran_front's sss_level from 598.1 to 5491.7.
        warnings.warn(
            f"{name}: mask codes are 0 and 1 (of 0..{top:.0f}), as a boolean mask saved as "
            "integers is; read as 0 and 1",
            InputNotice,
            stacklevel=4,
        )
        return 1.0
    return top


def _note_mask_levels(mask: np.ndarray, name: str) -> None:
    """Warn when a mask's values look like something other than a skin mask.

    The model blends ``image + mask * (blurred - image)``: a mask whose values are
    all small blurs nothing, and one of mostly intermediate values (an image, or a
    mask saved at another scale) blurs each pixel partly.
    """
    largest = float(mask.max())
    if largest < MASK_FAINT:
        warnings.warn(
            f"{name}: the mask's largest value is {largest:.3g}, so no pixel is fully skin "
            "(expected 1 on skin, 0 elsewhere; was it saved at another scale?)",
            InputNotice,
            stacklevel=3,
        )
        return
    on = mask[mask > 0]
    soft = float(np.mean((on > 1.0 / 255.0) & (on < 1.0 - 1.0 / 255.0)))
    if soft > MASK_SOFT_SHARE:
        warnings.warn(
            f"{name}: {soft:.0%} of the mask's non-zero pixels lie between 0 and 1 "
            "(expected a mask of 0 and 1 with at most a soft rim; is it an image?)",
            InputNotice,
            stacklevel=3,
        )


def load_pair(
    source, target, depth, mask, depth_scale: float = 1.0, *, linear_codes: bool = False
) -> ImagePair:
    """Read and cross-check the four files of one example.

    Parameters
    ----------
    source, target : str or os.PathLike
        Images for :func:`read_image`, 1 or 3 channels each.
    depth : str or os.PathLike
        Depth for :func:`read_depth`, multiplied by ``depth_scale``.
    mask : str or os.PathLike
        Mask for :func:`read_mask`.
    depth_scale : float
        Multiplies the stored depth (unit conversion).
    linear_codes : bool
        Integer codes of the source and target are linear (``linear=True`` of
        :func:`read_image`).

    Returns
    -------
    ImagePair

    Raises
    ------
    InvalidInputError
        Anything the readers reject, a file whose size differs from the source's,
        a target whose channels do not fit the source's (1 or the same count), or
        masked pixels without finite depth > 0 (off the mask, 0 or infinite depth
        is accepted and replaced, see :func:`invsss.forward.pair.fill_background_depth`).

    Warns
    -----
    InputNotice
        The mask likely includes background (see
        :func:`invsss.validation.check_mask_background`), the target is a
        JPEG (its compression biases the fitted blur, docs/capture.md), or an
        image is a grey stored as three identical channels (to within the
        file's precision; a JPEG's to within :data:`JPEG_GREY_CODES`), which is
        read as one channel: the target always, the source when the target is
        grey (a grey source before a colour target stays RGB).

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> d = tempfile.mkdtemp(); p = lambda n: os.path.join(d, n)
    >>> invsss.write_image(p("s.exr"), np.ones((4, 6, 3), np.float32) * np.float32([1.0, 0.5, 0.25]))
    >>> invsss.write_image(p("t.exr"), np.ones((4, 6), np.float32))
    >>> np.save(p("d.npy"), np.full((4, 6), 500.0)); np.save(p("m.npy"), np.eye(4, 6))
    >>> pair = invsss.load_pair(p("s.exr"), p("t.exr"), p("d.npy"), p("m.npy"))
    >>> pair.source.shape, pair.target.shape, pair.depth.shape
    ((4, 6, 3), (4, 6, 1), (4, 6))
    """
    source_image, source_grey = _read_colour(source, linear_codes)
    target_image, target_grey = _read_colour(target, linear_codes)
    depth_map = read_depth(depth, scale=depth_scale)
    mask_map = read_mask(mask)
    names = {"source": source, "target": target, "depth": depth, "mask": mask}
    names = {k: os.fspath(v) for k, v in names.items()}
    # A grey photograph stored as RGB fitted as three photographs gets a weight per
    # channel from one channel's information (fran_front: sss_level 1081.7 against
    # 598.1 from the same target stored as one channel).
    if target_grey:
        target_image = _one_channel(target_image)
        _note_grey(names["target"], "")
    # A grey source stays RGB before a colour target (each channel gets its weights);
    # before a grey one its mix to grey would be undetermined.
    if source_grey and target_image.shape[2] == 1:
        source_image = _one_channel(source_image)
        _note_grey(names["source"], ", as the target is grey")
    check_pair(source_image, target_image, depth_map, mask_map, names)
    if image_extension(names["target"], "image") in (".jpg", ".jpeg"):
        # Measured (docs/capture.md): JPEG q90 of a model-made face moved sss_level
        # +1 to +3 % fitted plainly and +6 % with registration, about 2 standard errors.
        warnings.warn(
            f"{names['target']}: a JPEG target: its compression removes fine detail, which the fit reads as "
            "a wider blur (sss_level +1 to +6 % on a simulated face, docs/capture.md); prefer RAW or PNG",
            InputNotice,
            stacklevel=2,
        )
    # Background depth as a renderer writes it (0, inf) is replaced here, so
    # pair.depth is safe to pass to render() or any other model code.
    return ImagePair(source_image, target_image, fill_background_depth(depth_map), mask_map)


# ------------------------------------------------------------------------ writing


@contextlib.contextmanager
def _atomic_target(path: str):
    """Yield a temporary sibling of ``path``; on success it replaces ``path``."""
    directory, base = os.path.split(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise InvalidInputError(f"{path}: cannot write, directory {directory} does not exist")
    ext = os.path.splitext(base)[1]
    # Same directory (so os.replace is a rename on one file system) and the same
    # extension (OpenImageIO picks the format from it); hidden while incomplete.
    temporary = os.path.join(directory, f".{base}.{secrets.token_hex(4)}.tmp{ext}")
    try:
        yield temporary
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(temporary)
        raise


def write_text_atomic(path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` so that an interrupted run leaves no half file."""
    with _atomic_target(os.fspath(path)) as temporary:
        with open(temporary, "x", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())


def _encode(image: np.ndarray, bits: int, ext: str) -> tuple[np.ndarray, str, str | None]:
    """Pixels for the file, their OpenImageIO type and the colour space to declare."""
    if bits == 32:
        return image.astype(np.float32), "float", None
    if bits == 16 and ext == ".exr":
        return image.astype(np.float32), "half", None
    if bits == 8:
        encoded = linear_to_srgb(np.clip(image, 0.0, 1.0))
        return np.round(encoded * 255.0).astype(np.uint8), "uint8", "srgb_rec709_scene"
    linear = np.clip(image.astype(np.float64), 0.0, 1.0)
    # Declared linear: a PNG gets gAMA = 1.0, so any reader knows it is not sRGB.
    return np.round(linear * 65535.0).astype(np.uint16), "uint16", "lin_rec709_scene"


def write_image(path, image, *, bits: int | None = None) -> None:
    """Write a linear float image, encoded for the file type, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        ``.exr``, ``.png``, ``.tif``/``.tiff``, ``.jpg``/``.jpeg`` or ``.npy``.
    image : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear values; must be finite.
    bits : int, optional
        32: float (default for EXR, TIFF, NPY). 16: half for EXR, else 16-bit
        linear integers declared linear. 8: sRGB-encoded bytes (default for PNG
        and JPEG). Integer encodings clip to [0, 1] first.

    Raises
    ------
    InvalidInputError
        Bad shape or values, unsupported extension or bit depth, a missing
        directory, or a write failure.

    Examples
    --------
    >>> import numpy as np, tempfile, os, invsss
    >>> path = os.path.join(tempfile.mkdtemp(), "out.exr")
    >>> invsss.write_image(path, np.full((4, 4, 3), 0.25, np.float32))
    >>> float(invsss.read_image(path).mean())
    0.25
    """
    name = os.fspath(path)
    ext = image_extension(name, "image")
    bits = _DEFAULT_BITS[ext] if bits is None else bits
    if bits not in _ALLOWED_BITS[ext]:
        raise InvalidInputError(
            f"{name}: cannot write {bits}-bit {ext} files, expected bits in {_ALLOWED_BITS[ext]}"
        )
    image = np.asarray(image)
    check_image(image, f"image for {name}")
    if image.ndim == 2:
        image = image[..., None]
    pixels, pixel_type, colour_space = _encode(image, bits, ext)
    # OpenImageIO takes C-ordered pixels only; a read image or a slice may be strided.
    pixels = np.ascontiguousarray(pixels)

    with _atomic_target(name) as temporary:
        if ext == ".npy":
            with open(temporary, "xb") as f:
                np.save(f, pixels if pixels.shape[2] > 1 else pixels[..., 0])
            return
        oiio = _oiio()
        height, width, channels = pixels.shape
        spec = oiio.ImageSpec(width, height, channels, pixel_type)
        if colour_space is not None:
            spec.attribute("oiio:ColorSpace", colour_space)
        if ext in (".jpg", ".jpeg"):
            # High quality and no chroma subsampling: these are data, not thumbnails.
            spec.attribute("Compression", "jpeg:95")
            spec.attribute("jpeg:subsampling", "4:4:4")
        output = oiio.ImageOutput.create(temporary)
        if output is None:
            raise InvalidInputError(f"{name}: cannot write ({_one_line(oiio.geterror())})")
        ok = output.open(temporary, spec) and output.write_image(pixels)
        error = _one_line(output.geterror())
        ok = output.close() and ok
        if not ok:
            raise InvalidInputError(f"{name}: cannot write ({error or 'unknown error'})")
