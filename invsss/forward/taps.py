"""The seven taps of a directional pass and the pass in plain XLA (docs/model.md, section 3).

A pass reads each pixel's row (or column) at a few real-valued positions with
linear interpolation and clamp-to-edge addressing, and mixes the samples. The
sample positions depend on the parameters, so gradients with respect to the
parameters flow through the slope of the interpolation.

:func:`directional_pass_xla` is the reference every other implementation of
the pass is checked against (:mod:`invsss.forward.pass_kernels`); the pass the
models call, with its GPU dispatch, is :func:`invsss.forward.passes.directional_pass`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .arrays import float_array

__all__ = [
    "TAP_OFFSETS",
    "TAP_WEIGHTS",
    "tap_weights",
    "tap_spread",
    "sample_along",
    "tap_sum",
    "pixel_coordinates",
    "directional_pass_xla",
]

#: Tap positions ``t_k = k / 3``, ``k = -3..3``, as fractions of the footprint.
TAP_OFFSETS = tuple(k / 3.0 for k in range(-3, 4))

#: The two published 7-tap weight sets (docs/model.md, section 3).
TAP_WEIGHTS = {
    # Jimenez 2009 demo shader: unit-normal mass over unit bins.
    "jimenez": (0.006, 0.061, 0.242, 0.382, 0.242, 0.061, 0.006),
    # The thesis's Listing 4.1: a nearly flat kernel.
    "thesis": (0.1053, 0.1402, 0.1664, 0.1762, 0.1664, 0.1402, 0.1053),
}


def tap_weights(spec="jimenez", dtype=None) -> Float[Array, " 7"]:
    """The 7 tap weights named by ``spec`` ("jimenez", "thesis") or given as numbers."""
    if isinstance(spec, str):
        if spec not in TAP_WEIGHTS:
            raise ValueError(
                f"tap_weights: expected one of {sorted(TAP_WEIGHTS)} or 7 numbers, got {spec!r}"
            )
        spec = TAP_WEIGHTS[spec]
    w = float_array(spec, dtype)
    if w.shape != (7,):
        raise ValueError(f"tap_weights: expected 7 numbers, got shape {w.shape}")
    return w


def tap_spread(weights: Float[Array, " 7"]) -> Float[Array, ""]:
    """``c_W = sqrt(sum_k W_k t_k^2)``: a footprint ``f`` blurs with std ``c_W * f`` pixels."""
    t = jnp.asarray(TAP_OFFSETS, dtype=weights.dtype)
    return jnp.sqrt(jnp.sum(weights * t**2))


def sample_along(
    image: Float[Array, "H W C"], positions: Float[Array, "H W *T"], axis: int
) -> Float[Array, "H W *T C"]:
    """Read ``image`` at real ``positions`` along rows (``axis=1``) or columns (``axis=0``).

    ``positions[y, x]`` (or ``positions[y, x, t]`` for several taps) is a
    coordinate along the axis for output pixel ``(y, x)``; the other coordinate
    is the pixel's own. Linear interpolation between the two nearest pixel
    centres, coordinates clamped to ``[0, n - 1]`` (clamp-to-edge). At an
    integer coordinate the derivative uses the slope to the right (to the left
    at ``n - 1``).
    """
    if positions.ndim == 3:
        # Callers that sum over taps should pass one (H, W) tap at a time: XLA
        # fuses each gather into the running sum, while one stacked
        # (H, W, T, C) gather measured 15-20x slower per pass on CPU.
        taps = [_sample_one(image, positions[..., t], axis) for t in range(positions.shape[2])]
        return jnp.stack(taps, axis=2)
    return _sample_one(image, positions, axis)


def _sample_one(image, positions, axis):
    h, w, c = image.shape
    # ``axis`` may be a Python int or a traced scalar (the models scan over
    # alternating passes with one body), so both layouts go through jnp.where.
    along_rows = jnp.asarray(axis) == 1
    n = jnp.where(along_rows, w, h)
    u = jnp.clip(positions, 0.0, (n - 1).astype(positions.dtype))
    i0 = jnp.clip(jnp.floor(u).astype(jnp.int32), 0, n - 2)
    frac = (u - i0)[..., None]
    # Gather from the flattened image; the indices are in bounds by
    # construction, so XLA's bounds handling is skipped.
    rows = jnp.arange(h, dtype=jnp.int32)[:, None]
    cols = jnp.arange(w, dtype=jnp.int32)[None, :]
    flat0 = jnp.where(along_rows, rows * w + i0, i0 * w + cols)
    step = jnp.where(along_rows, 1, w)
    flat = image.reshape(h * w, c)
    left = flat.at[flat0].get(mode="promise_in_bounds")
    right = flat.at[flat0 + step].get(mode="promise_in_bounds")
    return left + frac * (right - left)


def pixel_coordinates(shape, axis, dtype):
    """Each pixel's own coordinate along ``axis`` (x for 1, y for 0), shape (H, W)."""
    h, w = shape[:2]
    xs = jnp.broadcast_to(jnp.arange(w, dtype=dtype)[None, :], (h, w))
    ys = jnp.broadcast_to(jnp.arange(h, dtype=dtype)[:, None], (h, w))
    return jnp.where(jnp.asarray(axis) == 1, xs, ys)


def directional_pass_xla(image, footprint, mask, weights, axis):
    """:func:`invsss.forward.passes.directional_pass` in plain XLA: the reference.

    ``image`` (H, W, C), ``footprint`` and ``mask`` (H, W), ``weights`` (7,),
    ``axis`` 1 (horizontal) or 0 (vertical); returns (H, W, C).
    """
    blurred = _tap_sum_traced_once(image, footprint, weights, axis)
    # I + m (P - I) equals m P + (1 - m) I and returns I bit-exactly where m = 0.
    return image + mask[..., None] * (blurred - image)


def tap_sum(image, footprint, weights, axis):
    """``sum_k weights[k] image(x + t_k footprint(x))`` along ``axis``: a pass before the mask.

    ``image`` (H, W, C), ``footprint`` (H, W), ``weights`` (7,); returns (H, W, C).
    The pass's weights tangent is this sum with the tangent's weights.
    """
    base = pixel_coordinates(image.shape, axis, image.dtype)
    # The centre tap (t = 0) reads the pixel itself; the other six are gathered
    # one at a time so that each gather fuses into the running sum.
    total = weights[3] * image
    for k, t in enumerate(TAP_OFFSETS):
        if t != 0.0:
            total = total + weights[k] * sample_along(image, base + t * footprint, axis)
    return total


#: :func:`tap_sum` as a jitted function: a fit traces the blur many times over (the
#: start scan, each Jacobian, the solver's init and step), and inside a trace a jitted
#: call with the same shapes is traced once and reused, where the plain function's
#: six gathers are traced again at every call.
_tap_sum_traced_once = jax.jit(tap_sum)
