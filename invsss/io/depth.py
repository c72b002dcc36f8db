"""Reading depth maps: linear eye-space depth, stored as data.

A depth file's integer codes are never colour-decoded (a 16-bit PNG's codes
times a scale are the depth, as depth cameras store millimetres); 8-bit depth is
refused as too coarse. Every failure raises
:class:`~invsss.validation.InvalidInputError` with one line that names the file
and what was expected.
"""

from __future__ import annotations

import math

import numpy as np

from ..validation import InvalidInputError, depth_is_valid
from .rasters import code_bits, read_raster

__all__ = ["read_depth"]

_DEPTH_FORMATS = "expected float EXR, NPY, or 16-bit PNG with a scale"


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
    name, raster = read_raster(path, "depth")
    codes = raster.codes[..., 0]
    bits = code_bits(codes)
    if bits == 8:
        raise InvalidInputError(f"{name}: 8-bit depth is too coarse, {_DEPTH_FORMATS}", field=name)
    if bits is not None and raster.file_format != "npy" and codes.dtype != np.uint16:
        raise InvalidInputError(f"{name}: unsupported depth type {codes.dtype}, {_DEPTH_FORMATS}", field=name)
    depth = (codes.astype(np.float64) * scale).astype(np.float32)
    if depth.shape[0] < 2 or depth.shape[1] < 2:
        raise InvalidInputError(f"{name}: expected at least 2x2 pixels, got {depth.shape}", field=name)
    if not depth_is_valid(depth).any():
        raise InvalidInputError(f"{name}: expected finite depth > 0 on the skin, no pixel has it", field=name)
    return depth
