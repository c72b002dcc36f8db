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
colour-decoded (:mod:`~invsss.io.depth`, :mod:`~invsss.io.masks`); files are
written by :mod:`~invsss.io.writing`, and read as stored by
:mod:`~invsss.io.rasters`. Every failure raises
:class:`~invsss.validation.InvalidInputError` with one line that names the file
and what was expected.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..forward.pair import ImagePair, fill_background_depth
from ..validation import InputNotice, InvalidInputError, check_image, check_pair
from .colour import srgb_to_linear
from .depth import read_depth
from .masks import read_mask
from .rasters import Raster, checked_path, code_bits, image_extension, open_input, openimageio, read_raster

__all__ = [
    "JPEG_GREY_CODES",
    "clipping_level",
    "finish_pair",
    "is_grey_rgb",
    "load_pair",
    "read_colour_pair",
    "read_image",
    "resolved_saturation",
    "shared_clipping_level",
]


def _decode_colour(raster: Raster, linear: bool = False) -> tuple[np.ndarray, str | float | None, bool]:
    """Linear float values from stored codes, by the rule in the module docstring.

    Returns the values, the transfer function undone ("srgb", a gamma, or None
    for float data) and whether it was assumed (the file does not say, and
    ``linear`` was not given). ``linear=True`` takes integer codes as linear values.
    """
    codes = raster.codes
    bits = code_bits(codes)
    if bits is None:
        return codes.astype(np.float32), None, False
    c = codes.astype(np.float64) / float(2**bits - 1)
    encoding = raster.encoding
    if encoding == "srgb" and bits > 8 and raster.file_format == "png":
        encoding = None  # OpenImageIO's default label for every PNG: no information
    assumed = encoding is None and not linear
    if encoding is None:
        encoding = "srgb" if bits == 8 else 1.0
    if linear:
        encoding = 1.0
    decoded = srgb_to_linear(c) if isinstance(encoding, str) else c**encoding  # a str is "srgb"
    return decoded.astype(np.float32), encoding, assumed


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
    name, raster = read_raster(path, "image")
    if raster.file_format == "npy" and raster.codes.dtype.kind != "f":
        raise InvalidInputError(
            f"{name}: expected a float NPY array of linear values, got {raster.codes.dtype} "
            "(save integer-coded images as PNG or TIFF so their encoding is known)",
            field=name,
        )
    image, encoding, assumed = _decode_colour(raster, linear)
    if encoding == "srgb":
        warnings.warn(
            f"{name}: {code_bits(raster.codes)}-bit codes decoded as sRGB to linear values "
            "(if they are linear already, use linear=True / --linear-codes)",
            InputNotice,
            stacklevel=3,
        )
    elif assumed:
        # The other half of the rule, said as the 8-bit half is: a 16-bit PNG exported
        # from an image editor is sRGB, and read as linear it fitted sss_level 1013
        # where the same image in linear codes gave 598 (fran_front's target).
        warnings.warn(
            f"{name}: {code_bits(raster.codes)}-bit codes read as linear values (the file does not say; "
            "if they are sRGB-encoded, convert the image to linear, e.g. a float EXR)",
            InputNotice,
            stacklevel=3,
        )
    if image.shape[2] not in (1, 3):
        raise InvalidInputError(
            f"{name}: expected 1 or 3 colour channels (plus optional alpha), got {image.shape[2]}",
            field=name,
        )
    check_image(image, name)
    return np.ascontiguousarray(image), is_grey_rgb(raster)


#: How far apart, in 8-bit codes, a JPEG's channels may lie and still be one grey.
#: A grey pixel has chroma Cb = Cr = 128 exactly, a flat plane that neither chroma
#: subsampling nor quantisation changes: libjpeg (through OpenImageIO) decoded
#: grey JPEGs to identical channels at 4:4:4, 4:2:2 and 4:2:0, quality 50-100.
#: One code allows for decoders that round each channel on its own; a tint of
#: two codes survives JPEG as two codes, so it is still read as colour.
JPEG_GREY_CODES = 1


def is_grey_rgb(raster: Raster) -> bool:
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
    >>> photo, render = os.path.join(folder, "photo.png"), os.path.join(folder, "render.exr")
    >>> invsss.clipping_level(photo), invsss.clipping_level(render)
    (1.0, None)
    """
    name, ext = checked_path(path, "image")
    if ext == ".npy":
        # read_image accepts float arrays only: nothing to clip.
        return None
    oiio = openimageio()
    image_input = open_input(name, "image")
    try:
        basetype = image_input.spec().format.basetype
    finally:
        image_input.close()
    return 1.0 if basetype in (oiio.UINT8, oiio.UINT16) else None


def resolved_saturation(level, target_paths) -> float | None:
    """A fit's ``saturation`` with ``"auto"`` replaced by the targets' own level.

    ``"auto"`` becomes :func:`shared_clipping_level` of ``target_paths``; a number
    or None is returned as it is. The command line and sweeps call this before
    the fit: the fit itself sees only arrays, which do not say how they were coded.

    Examples
    --------
    >>> resolved_saturation(0.9, [])
    0.9
    >>> print(resolved_saturation(None, ["anything.png"]))
    None
    """
    return shared_clipping_level(target_paths) if level == "auto" else level


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
    known = [level for level in levels.values() if level is not None]
    if not floats:
        return min(known) if known else None
    if len(floats) < len(levels):
        warnings.warn(
            f"saturation auto: no clipping level set, as a float target ({', '.join(floats)}) may hold values "
            "above 1; give the level to leave the integer-coded targets' clipped pixels out",
            InputNotice,
            stacklevel=2,
        )
    return None


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
    source_image, target_image = read_colour_pair(source, target, linear_codes)
    depth_map = read_depth(depth, scale=depth_scale)
    mask_map = read_mask(mask)
    names = {"source": source, "target": target, "depth": depth, "mask": mask}
    return finish_pair(source_image, target_image, depth_map, mask_map, {k: os.fspath(v) for k, v in names.items()})


def read_colour_pair(source, target, linear_codes: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The decoded source and target images of a pair, (H, W, C) each, with the grey rule
    of :func:`load_pair` applied (a grey target is one channel, and so is a grey source
    before a grey target)."""
    source_image, source_grey = _read_colour(source, linear_codes)
    target_image, target_grey = _read_colour(target, linear_codes)
    names = {"source": os.fspath(source), "target": os.fspath(target)}
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
    return source_image, target_image


def finish_pair(source_image, target_image, depth_map, mask_map, names: dict) -> ImagePair:
    """The checked :class:`ImagePair` of arrays read from the files ``names`` (keys
    ``source``, ``target``, ``depth``, ``mask``: what the messages call them)."""
    check_pair(source_image, target_image, depth_map, mask_map, names)
    if image_extension(names["target"], "image") in (".jpg", ".jpeg"):
        # Measured (docs/capture.md): JPEG q90 of a model-made face moved sss_level
        # +1 to +3 % fitted plainly and +6 % with registration, about 2 standard errors.
        warnings.warn(
            f"{names['target']}: a JPEG target: its compression removes fine detail, which the fit reads as "
            "a wider blur (sss_level +1 to +6 % on a simulated face, docs/capture.md); prefer RAW or PNG",
            InputNotice,
            stacklevel=3,
        )
    # Background depth as a renderer writes it (0, inf) is replaced here, so
    # pair.depth is safe to pass to render() or any other model code.
    return ImagePair(source_image, target_image, fill_background_depth(depth_map), mask_map,
                     inputs_noted=True)
