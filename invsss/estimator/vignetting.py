"""A camera's fall-off toward the corners, fitted as a smooth gain field.

Lenses pass less light to the edges of the frame than to its centre. A fit that
ignores this reads the darker periphery as something the scattering model must
explain; measured on a model-made face (experiments/photo_robustness.py), 20 %
at the corners moved ``correction`` by half. With ``vignetting=True`` the prediction becomes

    pred = V(rho) * gain * out + offset,    V(rho) = 1 + a_1 rho^2 + a_2 rho^4,

where ``rho`` is the distance of a pixel from the centre of the target's frame
divided by the half-diagonal (1 at the corners), the usual even polynomial of
radial fall-off. The offset (a black level) is not shaded. ``a = (a_1, a_2)`` is
one pair of numbers for all pairs of a joint fit (one camera) and all channels.

For fixed ``a`` the field multiplies every basis image, so the gains, weights
and offsets are still solved in closed form; ``a`` joins the nonlinear unknowns
(:mod:`.parametrisation`, block ``"vignetting"``, starting at 0), and the
Gauss-Newton covariance therefore includes it: the standard errors of the
scattering parameters account for the field being estimated. The field is
centred on the frame, which assumes the optical axis passes through the image
centre (true of an uncropped photograph).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = ["ORDER", "radius_squared", "vignetting_field", "vignetting_at"]

#: Number of coefficients: the rho^2 and rho^4 terms.
ORDER = 2


def radius_squared(shape: tuple[int, int], dtype=jnp.float64) -> Float[Array, "H W"]:
    """``rho^2``: squared distance from the frame's centre over the squared half-diagonal.

    Examples
    --------
    >>> import jax
    >>> rho2 = radius_squared((3, 5), jnp.float32)
    >>> float(rho2[1, 2]), float(rho2[0, 0]), float(rho2[2, 4])
    (0.0, 1.0, 1.0)
    """
    h, w = shape
    y = jnp.arange(h, dtype=dtype) - (h - 1) / 2.0
    x = jnp.arange(w, dtype=dtype) - (w - 1) / 2.0
    corner = ((h - 1) / 2.0) ** 2 + ((w - 1) / 2.0) ** 2
    return (y[:, None] ** 2 + x[None, :] ** 2) / max(corner, 1.0)


def vignetting_field(coefficients: Float[Array, " 2"], shape: tuple[int, int]) -> Float[Array, "H W"]:
    """``V = 1 + a_1 rho^2 + a_2 rho^4`` on a frame of ``shape``.

    Parameters
    ----------
    coefficients : array, shape (2,)
        ``(a_1, a_2)``; a fall-off of 20 % at the corners with the rho^2 term alone is
        ``(-0.2, 0)``.
    shape : (H, W)

    Returns
    -------
    array, shape (H, W)

    Examples
    --------
    >>> v = vignetting_field(jnp.array([-0.2, 0.0]), (5, 5))
    >>> round(float(v[2, 2]), 6), round(float(v[0, 0]), 6)
    (1.0, 0.8)
    """
    rho2 = radius_squared(shape, jnp.result_type(coefficients))
    return 1.0 + coefficients[0] * rho2 + coefficients[1] * rho2**2


def vignetting_at(coefficients, points, shape: tuple[int, int]):
    """``V`` at any positions of a frame of ``shape``: (N, 2) (row, col) points -> (N,).

    The field as :func:`vignetting_field` defines it, in NumPy, read where a
    registration maps the source's pixels into the photograph: a registration
    compares the photograph with a prediction on the source's grid, and an
    unshaded prediction leaves the fall-off for the warp's scale to take.

    Examples
    --------
    >>> at = vignetting_at([-0.2, 0.0], np.array([[2.0, 2.0], [0.0, 0.0], [1.0, 2.0]]), (5, 5))
    >>> [round(float(v), 6) for v in at]
    [1.0, 0.8, 0.975]
    """
    h, w = shape
    a = np.asarray(coefficients, np.float64)
    points = np.asarray(points, np.float64)
    corner = max(((h - 1) / 2.0) ** 2 + ((w - 1) / 2.0) ** 2, 1.0)
    rho2 = ((points[:, 0] - (h - 1) / 2.0) ** 2 + (points[:, 1] - (w - 1) / 2.0) ** 2) / corner
    return 1.0 + a[0] * rho2 + a[1] * rho2**2

