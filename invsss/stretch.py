"""Jimenez's depth stretch factors (MODEL.md section 2, thesis eq. 3.8-3.9)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = ["depth_slopes", "stretch_factors"]


def depth_slopes(depth: Float[Array, "H W"]) -> tuple[Float[Array, "H W"], Float[Array, "H W"]]:
    """``(|dd/dx|, |dd/dy|)`` with ``numpy.gradient``'s stencil.

    Central differences inside, one-sided differences on the border: the
    convention MODEL.md fixes so that every implementation agrees.
    """
    ddy, ddx = jnp.gradient(depth)
    return jnp.abs(ddx), jnp.abs(ddy)


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
    s_x = sss_level / (depth + correction * jnp.minimum(slope_x, maxdd))
    s_y = sss_level / (depth + correction * jnp.minimum(slope_y, maxdd))
    return s_x, s_y
