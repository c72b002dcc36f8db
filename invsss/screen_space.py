"""The three screen-space subsurface-scattering models (MODEL.md section 5).

``sog`` (default)
    The sum-of-Gaussians profile realised as d'Eon & Luebke do: blur layers of
    increasing variance, each one pass pair on top of the last, mixed by the weights.
``thesis``
    The thesis's shipped chain (Listing 4.1, Figure 4.10): K horizontal then K
    vertical passes; the weights do not enter.
``separable``
    Jimenez et al. 2015 separable SSS: one pass pair with a precomputed N-tap kernel.

All functions are pure and compose with ``jax.jit``, ``jax.grad`` and ``jax.vmap``.
:func:`render` is the checked entry point; the ``render_*`` functions assume
valid (H, W, C) inputs.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .params import SSSParams
from .passes import directional_pass, sample_along, tap_spread
from .passes import tap_weights as tap_weight_set
from .profiles import sum_of_gaussians
from .stretch import stretch_factors
from .validation import InvalidInputError, check_depth, check_image, check_mask

__all__ = [
    "MODELS",
    "render",
    "render_sog",
    "render_thesis",
    "render_separable",
    "sog_layers",
    "separable_kernel",
]

MODELS = ("sog", "thesis", "separable")


def _safe_sqrt(x):
    # sqrt with a zero derivative at 0: a zero-width pass is the identity, and the
    # derivative of the pass with respect to its footprint vanishes there, so the
    # true derivative is 0 * inf; we take the limit 0 rather than produce NaN.
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def sog_layers(
    image: Float[Array, "H W C"],
    depth: Float[Array, "H W"],
    mask: Float[Array, "H W"],
    sss_level,
    correction,
    maxdd,
    variances: Float[Array, " K"],
    tap_weights: Float[Array, "7"] | str = "jimenez",
) -> tuple[Float[Array, "K H W C"], Array]:
    """The blurred layers ``B_1..B_K`` of the ``sog`` model, by increasing variance.

    ``B_i = P_y(P_x(B_{i-1}; f_x,i); f_y,i)`` with ``B_0 = I`` and
    ``f_i = s * sqrt(v_i - v_{i-1}) / c_W``. Returns the stacked layers and the
    permutation that sorts ``variances`` (apply it to the weights). The estimator
    uses the layers directly: ``out`` is linear in them.
    """
    w_taps = tap_weight_set(tap_weights, image.dtype) if isinstance(tap_weights, str) else tap_weights
    c_w = tap_spread(w_taps)
    s_x, s_y = stretch_factors(depth, sss_level, correction, maxdd)
    order = jnp.argsort(variances)
    v = variances[order]
    widths = _safe_sqrt(jnp.diff(v, prepend=jnp.zeros((1,), v.dtype))) / c_w

    def blur_step(layer, width):
        layer = directional_pass(layer, s_x * width, mask, w_taps, axis=1)
        layer = directional_pass(layer, s_y * width, mask, w_taps, axis=0)
        return layer, layer

    # A scan keeps compile time independent of the number of Gaussians.
    _, layers = jax.lax.scan(blur_step, image, widths)
    return layers, order


def render_sog(image, depth, mask, params: SSSParams, tap_weights="jimenez"):
    """``out = sum_i w_i B_i / sum_i w_i`` (per channel for (K, C) weights)."""
    layers, order = sog_layers(
        image, depth, mask, params.sss_level, params.correction, params.maxdd,
        params.variances, tap_weights,
    )
    w = params.weights[order]
    w = w.reshape(w.shape[0], 1, 1, -1)  # (K, 1, 1, 1 or C)
    return jnp.sum(w * layers, axis=0) / jnp.sum(w, axis=0)


def render_thesis(image, depth, mask, params: SSSParams, tap_weights="thesis"):
    """K horizontal passes then K vertical passes with ``f_i = s sqrt(v_i) / c_W``."""
    w_taps = tap_weight_set(tap_weights, image.dtype) if isinstance(tap_weights, str) else tap_weights
    c_w = tap_spread(w_taps)
    s_x, s_y = stretch_factors(depth, params.sss_level, params.correction, params.maxdd)
    widths = _safe_sqrt(params.variances) / c_w

    def horizontal(layer, width):
        return directional_pass(layer, s_x * width, mask, w_taps, axis=1), None

    def vertical(layer, width):
        return directional_pass(layer, s_y * width, mask, w_taps, axis=0), None

    out, _ = jax.lax.scan(horizontal, image, widths)
    out, _ = jax.lax.scan(vertical, out, widths)
    return out


def separable_kernel(
    weights: Float[Array, "K *C"], variances: Float[Array, " K"], taps: int = 17, strength=1.0
) -> tuple[Float[Array, " N"], Float[Array, "N C"]]:
    """Jimenez 2015's precomputed kernel: offsets (scene units) and weights (N, C).

    Offsets ``o = sign(u) u^2 / R`` for ``u`` evenly spaced in ``[-R, R]`` (``R = 3``
    when ``taps > 20``, else 2), so samples crowd the centre; each weight is the
    profile at ``|o|`` times half the distance to its neighbours, normalised per
    channel, then blended with the identity by ``strength`` (scalar or per channel).
    """
    if taps < 3 or taps % 2 == 0:
        raise InvalidInputError(f"taps: expected an odd number >= 3, got {taps}")
    weights = jnp.asarray(weights)
    dtype = jnp.result_type(weights.dtype, jnp.asarray(variances).dtype)
    radius = 3.0 if taps > 20 else 2.0
    u = jnp.linspace(-radius, radius, taps, dtype=dtype)
    offsets = jnp.sign(u) * u**2 / radius
    gaps = jnp.abs(jnp.diff(offsets))
    zero = jnp.zeros((1,), dtype)
    area = 0.5 * (jnp.concatenate([zero, gaps]) + jnp.concatenate([gaps, zero]))
    profile = sum_of_gaussians(jnp.abs(offsets), weights, variances)
    profile = profile.reshape(taps, -1)
    kernel = area[:, None] * profile
    kernel = kernel / jnp.sum(kernel, axis=0)
    identity = jnp.zeros((taps, 1), dtype).at[taps // 2].set(1.0)
    strength = jnp.asarray(strength, dtype)
    return offsets, strength * kernel + (1.0 - strength) * identity


def _separable_pass(image, depth, mask, offsets_px, kernel, follow_surface, axis):
    coord = jnp.arange(image.shape[axis], dtype=image.dtype)
    base = coord[None, :] if axis == 1 else coord[:, None]
    positions = base[..., None] + offsets_px
    samples = sample_along(image, positions, axis)  # (H, W, N, C)
    if not (isinstance(follow_surface, (int, float)) and follow_surface == 0):
        sampled_depth = sample_along(depth[..., None], positions, axis)[..., 0]
        pull = jnp.clip(follow_surface * jnp.abs(sampled_depth - depth[..., None]), 0.0, 1.0)
        samples = samples + pull[..., None] * (image[:, :, None, :] - samples)
    blurred = jnp.einsum("hwnc,nc->hwc", samples, kernel)
    return image + mask[..., None] * (blurred - image)


def render_separable(
    image, depth, mask, params: SSSParams, taps: int = 17, strength=1.0, follow_surface=0.0
):
    """One horizontal and one vertical pass with the N-tap kernel at ``x + o L / d``."""
    offsets, kernel = separable_kernel(params.weights, params.variances, taps, strength)
    offsets = offsets.astype(image.dtype)
    kernel = kernel.astype(image.dtype)
    scale = params.sss_level / depth  # no correction term in this model
    offsets_px = scale[..., None] * offsets
    out = _separable_pass(image, depth, mask, offsets_px, kernel, follow_surface, axis=1)
    return _separable_pass(out, depth, mask, offsets_px, kernel, follow_surface, axis=0)


@eqx.filter_jit
def _render(image, depth, mask, params, model, tap_w, taps, strength, follow_surface):
    if model == "sog":
        return render_sog(image, depth, mask, params, tap_w)
    if model == "thesis":
        return render_thesis(image, depth, mask, params, tap_w)
    return render_separable(image, depth, mask, params, taps, strength, follow_surface)


def render(
    image: Float[Array, "H W *C"],
    depth: Float[Array, "H W"],
    mask: Float[Array, "H W"],
    params: SSSParams,
    model: str = "sog",
    *,
    tap_weights=None,
    taps: int = 17,
    strength=1.0,
    follow_surface=0.0,
) -> Float[Array, "H W *C"]:
    """Apply screen-space subsurface scattering to ``image``.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear radiance without scattering.
    depth : array, shape (H, W)
        Linear eye-space depth, > 0 (mm recommended).
    mask : array, shape (H, W)
        1 on skin, 0 elsewhere; fractional values blend.
    params : SSSParams
        Stretch-factor and profile parameters. Weights of shape (K, C) must have
        the image's C.
    model : {"sog", "thesis", "separable"}
    tap_weights : {"jimenez", "thesis"} or 7 numbers, optional
        Tap weights of the 7-tap passes; default "jimenez" for ``sog`` and
        "thesis" for ``thesis``. Not used by ``separable``.
    taps, strength, follow_surface
        ``separable`` only: kernel size (odd; 11, 17 or 25 in Jimenez's code), blend
        with the identity (scalar or per channel), and the follow-surface factor
        ``k`` in ``lerp(sample, centre, clamp(k |d_s - d_c|, 0, 1))`` (0 disables it).

    Returns
    -------
    array, same shape as ``image``

    Examples
    --------
    >>> import jax.numpy as jnp, invsss
    >>> image = jnp.ones((8, 8, 3)); depth = jnp.full((8, 8), 500.0); mask = jnp.ones((8, 8))
    >>> p = invsss.SSSParams(1000.0, 0.0, 1.0, [0.5, 0.5], [0.5, 2.0])
    >>> bool(jnp.allclose(invsss.render(image, depth, mask, p), 1.0))
    True
    """
    if model not in MODELS:
        raise InvalidInputError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    check_image(image)
    hw = tuple(np.shape(image)[:2])
    check_depth(depth, hw)
    check_mask(mask, hw)
    if not isinstance(params, SSSParams):
        raise InvalidInputError(f"params: expected invsss.SSSParams, got {type(params).__name__}")
    params.check()
    channels = np.shape(image)[2] if np.ndim(image) == 3 else 1
    if np.ndim(params.weights) == 2 and np.shape(params.weights)[1] not in (1, channels):
        raise InvalidInputError(
            f"params.weights: expected one column per image channel ({channels}), "
            f"got shape {np.shape(params.weights)}"
        )
    if tap_weights is None:
        tap_weights = "thesis" if model == "thesis" else "jimenez"
    dtype = jnp.result_type(float)
    image = jnp.asarray(image, dtype)
    squeeze = image.ndim == 2
    if squeeze:
        image = image[..., None]
    try:
        tap_w = tap_weight_set(tap_weights, dtype)
    except ValueError as err:
        raise InvalidInputError(str(err)) from None
    out = _render(
        image, jnp.asarray(depth, dtype), jnp.asarray(mask, dtype), params, model,
        tap_w, taps, strength, follow_surface,
    )
    return out[..., 0] if squeeze else out
