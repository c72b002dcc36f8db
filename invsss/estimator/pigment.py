"""The skin's pigment difference between source and target, fitted as a smooth gain field per channel.

Between a visible photograph and a 940 nm one of the same face, or between two colour
channels, the pigment (melanin, blood) shades the skin differently: a red nose and
cheeks, a bluish forehead (issue 47: about +-0.1 on values near 0.6 between a
portrait's green and red channels). One gain per channel cannot follow it, and the
blur is the only other thing the fit can change. With ``pigment=n`` the prediction becomes

    pred_c = P_c(u, v) * gain_c * out_c + offset_c,
    P_c = 1 + sum_j a_jc phi_j(u, v),

with ``phi`` the monomials of degree 1 to ``n`` in the frame's coordinates ``u``
(columns) and ``v`` (rows), each running from -1 to 1 across the frame: ``u, v`` for
degree 1, and ``u^2, u v, v^2`` added for degree 2. ``a = 0`` is the identity, so a fit
with the field contains the fit without it. The field is smooth over the whole face,
so it cannot reproduce a blur, which changes an image within a few pixels of every
edge; it takes the face-wide colour gradients a gain leaves. Pigment at the scale of
the blur (freckles that fade at 940 nm) is not smooth and stays in the residual; no
such field removes it (docs/capture.md, "Pigment").

For fixed ``a`` the field multiplies every basis image, so gains, weights and offsets
are still solved in closed form; ``a`` (one set per pair and target channel) joins
the nonlinear unknowns (block ``"pigment"``, starting at 0) and the covariance.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError

__all__ = ["DEGREES", "num_terms", "term_names", "pigment_field", "pigment_at"]

#: The field's allowed degrees; 0 is no field.
DEGREES = (0, 1, 2)


def _exponents(degree: int) -> list[tuple[int, int]]:
    return [(i, d - i) for d in range(1, degree + 1) for i in range(d, -1, -1)]


def num_terms(degree: int) -> int:
    """The number of monomials of degree 1 to ``degree`` in two variables.

    Examples
    --------
    >>> [num_terms(d) for d in DEGREES]
    [0, 2, 5]
    """
    if isinstance(degree, bool) or degree not in DEGREES:
        raise InvalidInputError(f"pigment: expected a degree among {', '.join(map(str, DEGREES))}, got {degree!r}",
                                field="pigment")
    return len(_exponents(degree))


def term_names(degree: int) -> list[str]:
    """The monomials in order, as params.json names them.

    Examples
    --------
    >>> term_names(2)
    ['u', 'v', 'u^2', 'u v', 'v^2']
    """
    def name(i, j):
        parts = [p for p in (("u" if i == 1 else f"u^{i}") if i else "", ("v" if j == 1 else f"v^{j}") if j else "")
                 if p]
        return " ".join(parts)

    num_terms(degree)
    return [name(i, j) for i, j in _exponents(degree)]


def _coordinates(rows, cols, shape):
    h, w = shape
    return (cols - (w - 1) / 2.0) / max((w - 1) / 2.0, 1.0), (rows - (h - 1) / 2.0) / max((h - 1) / 2.0, 1.0)


def pigment_field(coefficients: Float[Array, "T C"], shape: tuple[int, int]) -> Float[Array, "H W C"]:
    """``P_c = 1 + sum_j a_jc phi_j`` on a frame of ``shape``.

    Parameters
    ----------
    coefficients : array, shape (T, C)
        ``a``, one column per target channel; ``T`` is :func:`num_terms` of the degree.
    shape : (H, W)

    Returns
    -------
    array, shape (H, W, C)

    Examples
    --------
    >>> p = pigment_field(jnp.array([[0.1], [0.0]]), (3, 5))
    >>> [round(float(x), 6) for x in p[1, :, 0]]
    [0.9, 0.95, 1.0, 1.05, 1.1]
    """
    t = coefficients.shape[0]
    degree = {num_terms(d): d for d in DEGREES}.get(t)
    if degree is None:
        raise InvalidInputError(f"pigment coefficients: expected 0, 2 or 5 rows (terms), got {t}")
    dtype = jnp.result_type(coefficients)
    rows = jnp.arange(shape[0], dtype=dtype)[:, None]
    cols = jnp.arange(shape[1], dtype=dtype)[None, :]
    u, v = _coordinates(rows, cols, shape)
    field = jnp.ones(shape + (coefficients.shape[1],), dtype)
    for k, (i, j) in enumerate(_exponents(degree)):
        field = field + (u**i * v**j)[..., None] * coefficients[k]
    return field


def pigment_at(coefficients, points, shape: tuple[int, int]) -> np.ndarray:
    """``P`` at any positions of a frame of ``shape``: (N, 2) (row, col) points -> (N, C), NumPy.

    The field of :func:`pigment_field` where a registration maps the source's
    pixels into the photograph (as :func:`invsss.estimator.vignetting.vignetting_at`).

    Examples
    --------
    >>> pigment_at([[0.1], [0.0]], np.array([[1.0, 4.0], [1.0, 2.0]]), (3, 5)).ravel().round(6).tolist()
    [1.1, 1.0]
    """
    a = np.asarray(coefficients, np.float64)
    degree = {num_terms(d): d for d in DEGREES}[a.shape[0]]
    points = np.asarray(points, np.float64)
    u, v = _coordinates(points[:, 0], points[:, 1], shape)
    field = np.ones((points.shape[0], a.shape[1]))
    for k, (i, j) in enumerate(_exponents(degree)):
        field += (u**i * v**j)[:, None] * a[k]
    return field
