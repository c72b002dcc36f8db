"""The sRGB transfer function (IEC 61966-2-1), both directions.

The model works on linear light; 8-bit files are sRGB-encoded. These two pure
NumPy functions are the only place that knows the curve.
"""

from __future__ import annotations

import numpy as np

__all__ = ["srgb_to_linear", "linear_to_srgb"]


def srgb_to_linear(encoded):
    """The sRGB EOTF (IEC 61966-2-1): encoded values in [0, 1] to linear light.

    ``c / 12.92`` for ``c <= 0.04045``, else ``((c + 0.055) / 1.055) ** 2.4``.

    Examples
    --------
    >>> from invsss.io import srgb_to_linear
    >>> round(float(srgb_to_linear(0.5)), 6)
    0.214041
    """
    c = np.asarray(encoded, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear):
    """The inverse of :func:`srgb_to_linear`: linear light in [0, 1] to sRGB-encoded values.

    Examples
    --------
    >>> from invsss.io import linear_to_srgb, srgb_to_linear
    >>> round(float(linear_to_srgb(srgb_to_linear(0.5))), 6)
    0.5
    """
    x = np.asarray(linear, dtype=np.float64)
    return np.where(
        x <= 0.0031308, 12.92 * x, 1.055 * np.maximum(x, 0.0031308) ** (1.0 / 2.4) - 0.055
    )
