"""Radial diffusion profiles R(r) (MODEL.md section 4)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = ["gaussian", "sum_of_gaussians"]


def gaussian(variance, r):
    """Normalised 2D Gaussian ``G(v, r) = exp(-r^2 / (2 v)) / (2 pi v)`` (thesis eq. 4.1)."""
    return jnp.exp(-(r**2) / (2.0 * variance)) / (2.0 * jnp.pi * variance)


def sum_of_gaussians(
    r: Float[Array, "*N"], weights: Float[Array, "K *C"], variances: Float[Array, " K"]
) -> Float[Array, "*N *C"]:
    """``R(r) = sum_i w_i G(v_i, r)`` (thesis eq. 4.2, d'Eon & Luebke 2007).

    With per-channel weights of shape (K, C) the result gains a trailing C axis.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> float(sum_of_gaussians(jnp.array(0.0), jnp.array([1.0]), jnp.array([1.0 / (2 * jnp.pi)])))
    1.0
    """
    r = jnp.asarray(r)
    weights = jnp.asarray(weights)
    variances = jnp.asarray(variances)
    g = gaussian(variances, r[..., None])  # (*N, K)
    if weights.ndim == 1:
        return jnp.sum(g * weights, axis=-1)
    return jnp.einsum("...k,kc->...c", g, weights)
