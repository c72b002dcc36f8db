"""One directional pass of a screen-space blur (MODEL.md section 3).

A pass reads each pixel's row (or column) at a few real-valued positions with
linear interpolation and clamp-to-edge addressing, and mixes the samples. The
sample positions depend on the parameters, so gradients with respect to the
parameters flow through the slope of the interpolation.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = [
    "TAP_OFFSETS",
    "TAP_WEIGHTS",
    "tap_weights",
    "tap_spread",
    "sample_along",
    "directional_pass",
]

#: Tap positions ``t_k = k / 3``, ``k = -3..3``, as fractions of the footprint.
TAP_OFFSETS = tuple(k / 3.0 for k in range(-3, 4))

#: The two published 7-tap weight sets (MODEL.md section 3).
TAP_WEIGHTS = {
    # Jimenez 2009 demo shader: unit-normal mass over unit bins.
    "jimenez": (0.006, 0.061, 0.242, 0.382, 0.242, 0.061, 0.006),
    # The thesis's Listing 4.1: a nearly flat kernel.
    "thesis": (0.1053, 0.1402, 0.1664, 0.1762, 0.1664, 0.1402, 0.1053),
}


def tap_weights(spec="jimenez", dtype=None) -> Float[Array, "7"]:
    """The 7 tap weights named by ``spec`` ("jimenez", "thesis") or given as numbers."""
    if isinstance(spec, str):
        if spec not in TAP_WEIGHTS:
            raise ValueError(
                f"tap_weights: expected one of {sorted(TAP_WEIGHTS)} or 7 numbers, got {spec!r}"
            )
        spec = TAP_WEIGHTS[spec]
    w = jnp.asarray(spec, dtype=dtype or jnp.result_type(float))
    if w.shape != (7,):
        raise ValueError(f"tap_weights: expected 7 numbers, got shape {w.shape}")
    return w


def tap_spread(weights: Float[Array, "7"]) -> Float[Array, ""]:
    """``c_W = sqrt(sum_k W_k t_k^2)``: a footprint ``f`` blurs with std ``c_W * f`` pixels."""
    t = jnp.asarray(TAP_OFFSETS, dtype=weights.dtype)
    return jnp.sqrt(jnp.sum(weights * t**2))


def sample_along(
    image: Float[Array, "H W C"], positions: Float[Array, "H W T"], axis: int
) -> Float[Array, "H W T C"]:
    """Read ``image`` at real ``positions`` along rows (``axis=1``) or columns (``axis=0``).

    ``positions[y, x, t]`` is a coordinate along the axis for output pixel
    ``(y, x)``; the other coordinate is the pixel's own. Linear interpolation
    between the two nearest pixel centres, coordinates clamped to
    ``[0, n - 1]`` (clamp-to-edge). At an integer coordinate the slope used by
    the derivative is the one to the right (to the left at ``n - 1``).
    """
    h, w, c = image.shape
    n = image.shape[axis]
    u = jnp.clip(positions, 0.0, n - 1.0)
    i0 = jnp.clip(jnp.floor(u), 0, n - 2).astype(jnp.int32)
    frac = (u - i0)[..., None]
    # Gather from the flattened image: one index computation serves both axes.
    if axis == 1:
        rows = jnp.arange(h, dtype=jnp.int32)[:, None, None]
        flat0, step = rows * w + i0, 1
    else:
        cols = jnp.arange(w, dtype=jnp.int32)[None, :, None]
        flat0, step = i0 * w + cols, w
    flat = image.reshape(h * w, c)
    left = flat[flat0]
    right = flat[flat0 + step]
    return left + frac * (right - left)


def directional_pass(
    image: Float[Array, "H W C"],
    footprint: Float[Array, "H W"],
    mask: Float[Array, "H W"],
    weights: Float[Array, "7"],
    axis: int,
) -> Float[Array, "H W C"]:
    """``P(I; f)[y, x] = sum_k W_k I(y, x + t_k f[y, x])``, blended by the mask.

    ``axis=1`` is the horizontal pass ``P_x``, ``axis=0`` the vertical ``P_y``.
    Where ``mask`` is 0 the image is returned unchanged; in between the result
    is ``m P + (1 - m) I``.
    """
    t = jnp.asarray(TAP_OFFSETS, dtype=image.dtype)
    coord = jnp.arange(image.shape[axis], dtype=image.dtype)
    base = coord[None, :] if axis == 1 else coord[:, None]
    positions = base[..., None] + footprint[..., None] * t
    blurred = jnp.einsum("hwkc,k->hwc", sample_along(image, positions, axis), weights)
    # I + m (P - I) equals m P + (1 - m) I and returns I bit-exactly where m = 0.
    return image + mask[..., None] * (blurred - image)
