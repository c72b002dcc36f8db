"""Jimenez's depth stretch factors (docs/model.md, section 2, thesis eq. 3.8-3.9)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

__all__ = ["depth_slopes", "stretch_along", "stretch_factors"]


def depth_slopes(depth: Float[Array, "H W"]) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """``(|dd/dx|, |dd/dy|)`` with ``numpy.gradient``'s stencil.

    Central differences inside, one-sided differences on the border: the
    convention docs/model.md fixes so that every implementation agrees. A NumPy
    ``depth`` gives NumPy slopes (no compilation of eager JAX operations on the host).
    """
    xp = np if isinstance(depth, np.ndarray) else jnp
    ddy, ddx = xp.gradient(depth)
    return xp.abs(ddx), xp.abs(ddy)


def stretch_factors(
    depth: Float[Array, "H W"], sss_level, correction, maxdd
) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """Horizontal and vertical stretch factors ``(s_x, s_y)`` in pixels per scene unit.

    ``s = L / (d + c * min(|dd|, delta))``; a profile length of ``r`` covers
    ``s * r`` pixels.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> sx, sy = stretch_factors(jnp.full((4, 4), 2.0), 10.0, 5.0, 0.1)
    >>> float(sx[0, 0])
    5.0
    """
    slope_x, slope_y = depth_slopes(depth)
    s_x = stretch_along(depth, slope_x, sss_level, correction, maxdd)
    s_y = stretch_along(depth, slope_y, sss_level, correction, maxdd)
    return s_x, s_y


def stretch_along(depth, slope, sss_level, correction, maxdd, xp=jnp):
    """The stretch factor along one axis from the depth and that axis's slope magnitude.

    ``s = L / (d + c * min(slope, delta))``, elementwise, with ``slope >= 0``
    (:func:`depth_slopes`). ``xp`` is the array namespace: ``jax.numpy``, or
    ``numpy`` to stay in NumPy's float64 (as the estimator's data scales do).

    Examples
    --------
    >>> import numpy as np
    >>> stretch_along(np.array([2.0, 2.0]), np.array([0.0, 1.0]), 10.0, 5.0, 0.1, xp=np).tolist()
    [5.0, 4.0]
    """
    return sss_level / (depth + correction * xp.minimum(slope, maxdd))
