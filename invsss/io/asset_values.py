"""The values an engine asset is made from, checked once for both engines' exports.

:mod:`invsss.io.engine_profiles` (HDRP, Unreal's profile) and
:mod:`invsss.io.unreal_transmission` take a fit's Burley ``d`` and its
``transmission`` term from here, with one message per kind of bad value.
"""

from __future__ import annotations

import numpy as np

from ..validation import InvalidInputError, positive_number

__all__ = ["shape_parameters", "transmission_term"]


def shape_parameters(d, name="d") -> np.ndarray:
    """Burley's ``d`` (mm), one or three values > 0, as three, shape (3,).

    Examples
    --------
    >>> shape_parameters(2.0).tolist()
    [2.0, 2.0, 2.0]
    """
    d = np.asarray(d, np.float64).reshape(-1)
    if d.size not in (1, 3) or not np.all(np.isfinite(d)) or np.any(d <= 0):
        raise InvalidInputError(f"{name}: expected one or three shape parameters > 0 (mm), got {d.tolist()}",
                                field=name)
    return np.broadcast_to(d, (3,)).copy()


def transmission_term(tint, thickness_scale, d_mm, one_per_profile: str) -> tuple[np.ndarray, float, np.ndarray]:
    """A fitted ``transmission`` term's tint (per channel, >= 0), thickness scale ``k``
    (> 0) and the profile's ``d``, which must be one value for every channel: ``k`` is
    one number, and so is the engine field named by ``one_per_profile`` that carries it.

    Examples
    --------
    >>> tau, k, d = transmission_term(0.5, 0.3, 1.0, "HDRP's thickness remap")
    >>> tau.tolist(), k, d.tolist()
    ([0.5, 0.5, 0.5], 0.3, [1.0, 1.0, 1.0])
    """
    tau = np.broadcast_to(np.asarray(tint, np.float64).reshape(-1), (3,))
    if not np.all(np.isfinite(tau)) or np.any(tau < 0.0):
        raise InvalidInputError(f"light_terms.transmission: expected a tint >= 0 per channel, got {tau.tolist()}")
    k = positive_number(thickness_scale, "light_terms.thickness_scale")
    d = shape_parameters(d_mm, "d_mm")
    if np.ptp(d) > 1e-6 * d.max():
        raise InvalidInputError(
            f"light_terms: the transmission's thickness scale is one number, but Burley's d differs by channel "
            f"({', '.join(f'{x:.4g}' for x in d)} mm) and {one_per_profile} is one per profile: export the "
            "profile without the transmission, or fit a grey pair"
        )
    return tau, k, d
