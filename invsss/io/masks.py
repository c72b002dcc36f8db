"""Reading skin masks: values in [0, 1], stored as data.

A mask's integer codes are divided by their maximum with no colour decoding,
and a mask that looks like something else (a boolean mask saved as the codes 0
and 1, a faint or mostly grey mask) is read with a notice saying how. Every
failure raises :class:`~invsss.validation.InvalidInputError` with one line that
names the file and what was expected.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..validation import InputNotice, InvalidInputError
from .rasters import code_bits, read_raster

__all__ = ["MASK_FAINT", "MASK_SOFT_SHARE", "read_mask"]

#: A mask none of whose pixels reaches this is not a skin mask at full strength.
MASK_FAINT = 0.5
#: A mask with more than this share of its non-zero pixels strictly between
#: 0 and 1 (give or take one 8-bit code) is more than a binary mask with a soft rim.
MASK_SOFT_SHARE = 0.5


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
    name, raster = read_raster(path, "mask")
    codes = raster.codes[..., 0]
    bits = code_bits(codes)
    if bits is not None and raster.file_format != "npy":
        mask = codes.astype(np.float64) / _mask_top_code(codes, bits, name)
    else:
        mask = codes.astype(np.float64)
    mask = mask.astype(np.float32)
    if mask.shape[0] < 2 or mask.shape[1] < 2:
        raise InvalidInputError(f"{name}: expected at least 2x2 pixels, got {mask.shape}", field=name)
    if not np.all(np.isfinite(mask)) or mask.min() < 0 or mask.max() > 1:
        raise InvalidInputError(
            f"{name}: expected mask values in [0, 1], got range "
            f"[{float(np.nanmin(mask)):g}, {float(np.nanmax(mask)):g}]"
            + (" with NaN" if np.any(np.isnan(mask)) else "")
        )
    if not np.any(mask > 0):
        raise InvalidInputError(f"{name}: mask is empty (no pixel > 0), expected some skin", field=name)
    _note_mask_levels(mask, name)
    return mask


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
