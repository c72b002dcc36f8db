"""The screen-space subsurface-scattering models (docs/model.md, section 5).

``sog`` (default)
    The sum-of-Gaussians profile realised as d'Eon & Luebke do: blur layers of
    increasing variance, each one pass pair on top of the last, mixed by the weights.
``thesis``
    The thesis's shipped chain (Listing 4.1, Figure 4.10): K horizontal then K
    vertical passes; the weights do not enter.
``separable``
    Jimenez et al. 2015 separable SSS: one pass pair with a precomputed N-tap kernel.
``burley``
    Burley's normalized diffusion sampled over a disk, as Unity HDRP and Unreal
    render it (:mod:`invsss.forward.burley_screen_space`).

:data:`invsss.forward.models.MODEL_TABLE` says what each one is; :func:`render`
dispatches on its ``layout``.

All functions are pure and compose with ``jax.jit``, ``jax.grad`` and ``jax.vmap``.
:func:`render` is the checked entry point; the ``render_*`` functions assume
valid (H, W, C) inputs.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError, check_depth, check_image, check_mask, is_concrete
from .burley_screen_space import check_burley_distances, render_burley
from .light_terms import AFTER_BLUR, LightBuffers, LightTerms, apply_law, apply_light_terms
from .models import MODEL_NAMES, get_model, resolve_tap_weights
from .pair import fill_background_depth
from .params import SSSParams, check_plausible
from .pass_plan import pass_plan
from .passes import directional_pass, pixel_coordinates, sample_along, tap_spread
from .passes import tap_weights as tap_weight_set
from .profiles import sum_of_gaussians
from .stretch import stretch_factors
from .transmission import apply_transmission

__all__ = [
    "MODELS",
    "render",
    "render_sog",
    "render_thesis",
    "render_separable",
    "sog_layers",
    "separable_kernel",
]

#: The model names (kept here for older imports; the table is :mod:`invsss.forward.models`).
MODELS = MODEL_NAMES


def _taps(spec, dtype):
    return tap_weight_set(spec, dtype) if isinstance(spec, str) else spec


def _pass_sequence(
    image, s_x, s_y, mask, w_taps, axes, widths, mix=None, slots=None, num_slots=0
):
    """Directional passes applied in sequence, pass ``j`` along ``axes[j]`` with
    footprint ``s * widths[j]``.

    Returns the last pass; with ``mix`` (one weight, or one per channel, per
    pass, summing to 1) the sum ``sum_j mix[j] * pass_j`` accumulated on the way; with
    ``slots`` a stack of ``num_slots`` passes, pass ``j`` stored at
    ``slots[j]`` (an index past the end discards it).

    Each pass is one scan step: a pass reads its input at data-dependent
    positions, and keeping passes in separate steps stops XLA from fusing a
    pass into the next one's gathers, which recomputes it once per tap (50x
    slower on CPU). One body also keeps compile time independent of K.
    Accumulating in the carry, rather than stacking every pass and summing
    afterwards, halves the time on CPU.
    """

    # INVSSS_SCAN_UNROLL=1 unrolls the scan (issue 35: measured on a GPU, where
    # a loop step costs launches and a host round trip; experiments/bench_forward.py).
    unroll = os.environ.get("INVSSS_SCAN_UNROLL", "0") == "1"

    # Reverse mode recomputes each pass from its input instead of storing the
    # twelve gathered images per pass: 24-32 % less time for value+grad on CPU.
    @jax.checkpoint
    def blur(layer, axis, width):
        footprint = jnp.where(axis == 1, s_x, s_y) * width
        return directional_pass(layer, footprint, mask, w_taps, axis)

    if mix is not None:

        # Accumulate mix * (pass - image) and add the image back at the end:
        # where the mask is 0 every pass equals the image bit-exactly, and so
        # does the result (a weighted mean of equal numbers can round).
        def step(carry, xs):
            layer, total = carry
            axis, width, weight = xs
            layer = blur(layer, axis, width)
            return (layer, total + weight * (layer - image)), None

        (_, total), _ = jax.lax.scan(step, (image, jnp.zeros_like(image)), (axes, widths, mix), unroll=unroll)
        return image + total
    if slots is not None:
        def step(carry, xs):
            layer, stack = carry
            axis, width, slot = xs
            layer = blur(layer, axis, width)
            return (layer, stack.at[slot].set(layer, mode="drop")), None

        stack = jnp.zeros((num_slots,) + image.shape, image.dtype)
        (_, stack), _ = jax.lax.scan(step, (image, stack), (axes, widths, slots), unroll=unroll)
        return stack
    out, _ = jax.lax.scan(lambda layer, xs: (blur(layer, *xs), None), image, (axes, widths), unroll=unroll)
    return out


def sog_layers(
    image: Float[Array, "H W C"],
    depth: Float[Array, "H W"],
    mask: Float[Array, "H W"],
    sss_level,
    correction,
    maxdd,
    variances: Float[Array, " K"],
    tap_weights: Float[Array, " 7"] | str = "jimenez",
) -> tuple[Float[Array, "K H W C"], Array]:
    """The blurred layers ``B_1..B_K`` of the ``sog`` model, by increasing variance.

    ``B_i = P_y(P_x(B_{i-1}; f_x,i); f_y,i)`` with ``B_0 = I`` and
    ``f_i = s * sqrt(v_i - v_{i-1}) / c_W``. Returns the stacked layers and the
    permutation that sorts ``variances`` (apply it to the weights). The estimator
    uses the layers directly: ``out`` is linear in them.
    """
    w_taps = _taps(tap_weights, image.dtype)
    s_x, s_y = stretch_factors(depth, sss_level, correction, maxdd)
    plan = pass_plan("layered", variances, tap_spread(w_taps), jnp)
    k = variances.shape[0]
    # Keep each vertical pass (B_i) in slot i; horizontal passes go to slot k,
    # which is out of range and dropped.
    slots = jnp.stack([jnp.full(k, k), jnp.arange(k)], axis=1).reshape(-1)
    axes = jnp.asarray(plan.axes, jnp.int32)
    layers = _pass_sequence(
        image, s_x, s_y, mask, w_taps, axes, plan.widths, slots=slots, num_slots=k
    )
    return layers, plan.order


def render_sog(image, depth, mask, params: SSSParams, tap_weights="jimenez"):
    """``out = sum_i w_i B_i / sum_i w_i`` (per channel for (K, C) weights)."""
    w_taps = _taps(tap_weights, image.dtype)
    s_x, s_y = stretch_factors(depth, params.sss_level, params.correction, params.maxdd)
    plan = pass_plan("layered", params.variances, tap_spread(w_taps), jnp)
    w = params.weights[plan.order]
    w = w.reshape(w.shape[0], -1) / jnp.sum(w.reshape(w.shape[0], -1), axis=0)  # (K, 1 or C)
    k = w.shape[0]
    # Pass pair i contributes its vertical pass, B_i, with weight w_i.
    mix = jnp.stack([jnp.zeros_like(w), w], axis=1).reshape(2 * k, 1, 1, -1)
    axes = jnp.asarray(plan.axes, jnp.int32)
    return _pass_sequence(image, s_x, s_y, mask, w_taps, axes, plan.widths, mix)


def render_thesis(image, depth, mask, params: SSSParams, tap_weights="thesis"):
    """K horizontal passes then K vertical passes with ``f_i = s sqrt(v_i) / c_W``."""
    w_taps = _taps(tap_weights, image.dtype)
    s_x, s_y = stretch_factors(depth, params.sss_level, params.correction, params.maxdd)
    plan = pass_plan("chained", params.variances, tap_spread(w_taps), jnp)
    axes = jnp.asarray(plan.axes, jnp.int32)
    return _pass_sequence(image, s_x, s_y, mask, w_taps, axes, plan.widths)


def separable_kernel(
    weights: Float[Array, " K *C"], variances: Float[Array, " K"], taps: int = 17, strength=1.0
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


def _separable_pass(image, depth, mask, offsets, scale, kernel, follow_surface, axis):
    base = pixel_coordinates(image.shape, axis, image.dtype)
    follow = not (isinstance(follow_surface, (int, float)) and follow_surface == 0)
    blurred = jnp.zeros_like(image)
    # One tap at a time so each gather fuses into the running sum (see passes.py).
    for j in range(offsets.shape[0]):
        positions = base + offsets[j] * scale
        sample = sample_along(image, positions, axis)
        if follow:
            sampled_depth = sample_along(depth[..., None], positions, axis)[..., 0]
            pull = jnp.clip(follow_surface * jnp.abs(sampled_depth - depth), 0.0, 1.0)
            sample = sample + pull[..., None] * (image - sample)
        blurred = blurred + kernel[j] * sample
    return image + mask[..., None] * (blurred - image)


def render_separable(
    image, depth, mask, params: SSSParams, taps: int = 17, strength=1.0, follow_surface=0.0
):
    """One horizontal and one vertical pass with the N-tap kernel at ``x + o L / d``."""
    offsets, kernel = separable_kernel(params.weights, params.variances, taps, strength)
    offsets = offsets.astype(image.dtype)
    kernel = kernel.astype(image.dtype)
    scale = params.sss_level / depth  # no correction term in this model

    def step(layer, axis):
        return _separable_pass(layer, depth, mask, offsets, scale, kernel, follow_surface, axis), None

    # Horizontal then vertical, as separate scan steps (see sog_layers).
    out, _ = jax.lax.scan(step, image, jnp.array([1, 0], jnp.int32))
    return out


def _render_kernel(image, depth, mask, params, tap_w, taps=17, strength=1.0, follow_surface=0.0):
    # The kernel layout has no 7-tap passes: tap_w is None and not used.
    return render_separable(image, depth, mask, params, taps, strength, follow_surface)


#: The renderer of each layout of :data:`invsss.forward.models.LAYOUTS`, called as
#: ``f(image, depth, mask, params, tap_w, **kernel_options)`` with (H, W, C)
#: inputs; only the kernel layout takes options.
LAYOUT_RENDERERS: dict[str, Callable[..., Any]] = {
    "layered": render_sog,
    "chained": render_thesis,
    "kernel": _render_kernel,
    "disk": render_burley,  # issue 34: invsss.forward.burley_screen_space
}


@eqx.filter_jit
def _render(image, depth, mask, params, model, tap_w, taps, strength, follow_surface):
    layout = get_model(model).layout
    options = (
        {"taps": taps, "strength": strength, "follow_surface": follow_surface}
        if layout == "kernel"
        else {}
    )
    return LAYOUT_RENDERERS[layout](image, depth, mask, params, tap_w, **options)


def _light_buffers(terms, buffers, hw, mask, channels) -> LightBuffers:
    if not isinstance(terms, LightTerms):
        raise InvalidInputError(f"light_terms: expected invsss.LightTerms, got {type(terms).__name__}",
                                field="light_terms")
    terms.check()
    if not isinstance(buffers, LightBuffers):
        raise InvalidInputError(
            "light_buffers: light_terms need an invsss.LightBuffers with the normal, light and/or key buffer, "
            f"got {type(buffers).__name__}"
        )
    buffers.require(terms.used)
    if terms.law is not None and np.ndim(terms.law) == 1 and np.shape(terms.law)[0] not in (1, channels):
        raise InvalidInputError(
            f"light_terms.law: expected one albedo or one per image channel ({channels}), "
            f"got {np.shape(terms.law)[0]}"
        )
    if np.ndim(terms.transmission) == 1 and np.shape(terms.transmission)[0] not in (1, channels):
        raise InvalidInputError(
            f"light_terms.transmission: expected one tint or one per image channel ({channels}), "
            f"got {np.shape(terms.transmission)[0]}",
            field="light_terms.transmission",
        )
    if not is_concrete(mask):
        return buffers
    return buffers.checked(hw, mask, channels=channels)


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
    light_terms: LightTerms | None = None,
    light_buffers: LightBuffers | None = None,
) -> Float[Array, "H W *C"]:
    """Apply screen-space subsurface scattering to ``image``.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear radiance without scattering.
    depth : array, shape (H, W)
        Linear eye-space depth, > 0 (mm recommended) where ``mask`` is 1 (on its soft
        edge it may be missing, and is filled like the background's);
        off the mask it may be 0 or infinite, as renderers write it.
    mask : array, shape (H, W)
        1 on skin, 0 elsewhere; fractional values blend.
    params : SSSParams
        Stretch-factor and profile parameters. Weights of shape (K, C) must have
        the image's C.
    model : {"sog", "thesis", "separable", "burley"}
        A name from :data:`invsss.forward.models.MODEL_NAMES`. ``burley`` reads
        ``variances`` as ``d^2`` per channel (:mod:`invsss.forward.burley_screen_space`).
    tap_weights : {"jimenez", "thesis"} or 7 numbers, optional
        Tap weights of the 7-tap passes; default the model's
        ``default_tap_weights`` ("jimenez" for ``sog``, "thesis" for
        ``thesis``). Not used by ``separable``.
    taps, strength, follow_surface
        ``separable`` only: kernel size (odd; 11, 17 or 25 in Jimenez's code), blend
        with the identity (scalar or per channel), and the follow-surface factor
        ``k`` in ``lerp(sample, centre, clamp(k |d_s - d_c|, 0, 1))`` (0 disables it).
    light_terms : LightTerms, optional
        The light-aware terms of docs/model.md, section 8: ``law`` and
        ``transmission`` change the image before the blur
        (:func:`invsss.forward.light_terms.apply_law`,
        :func:`invsss.forward.transmission.apply_transmission`), the others
        the blurred image (:func:`invsss.forward.light_terms.apply_light_terms`).
    light_buffers : LightBuffers, optional
        Their per-pixel buffers; required with ``light_terms``, and a term that is
        on (a parameter not 0; ``law`` not None) needs its buffers.

    Raises
    ------
    InvalidInputError
        For an input of the wrong shape, and, for concrete arrays, for values out
        of range (NaN or non-positive depth on the mask, a mask outside [0, 1],
        parameters outside their domain). Inside ``jax.jit``, ``grad`` or ``vmap``
        only shapes are checked: call ``render`` once on the concrete inputs first.

    Warns
    -----
    InputNotice
        For concrete valid but absurd parameters at this depth: the widest Gaussian
        wider than the image (depth in metres with parameters fitted in mm), or no
        visible blur at all (:func:`invsss.forward.params.check_plausible`).

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
    entry = get_model(model)
    check_image(image)
    height, width = np.shape(image)[:2]  # check_image has seen 2 or 3 axes
    hw = (height, width)
    check_mask(mask, hw)
    check_depth(depth, hw, mask=mask)
    # Renderer-style background depth (0, inf) must not reach the model: see
    # fill_background_depth.
    depth = fill_background_depth(depth)
    if not isinstance(params, SSSParams):
        raise InvalidInputError(f"params: expected invsss.SSSParams, got {type(params).__name__}")
    params.check()
    # Valid but absurd values (depth in metres for parameters fitted in mm blurs
    # 1000 times too wide) warn here, not only on the command line.
    check_plausible(params, depth)
    channels = np.shape(image)[2] if np.ndim(image) == 3 else 1
    if np.ndim(params.weights) == 2 and np.shape(params.weights)[1] not in (1, channels):
        raise InvalidInputError(
            f"params.weights: expected one column per image channel ({channels}), "
            f"got shape {np.shape(params.weights)}"
        )
    if entry.layout == "disk":  # issue 34: burley takes one d^2, or one per channel
        check_burley_distances(params.variances, channels)
    tap_weights = resolve_tap_weights(entry, tap_weights)
    dtype = jnp.result_type(float)
    image = jnp.asarray(image, dtype)
    squeeze = image.ndim == 2
    if squeeze:
        image = image[..., None]
    tap_w = None
    if tap_weights is not None:
        try:
            tap_w = tap_weight_set(tap_weights, dtype)
        except ValueError as err:
            raise InvalidInputError(str(err)) from None
    depth, mask = jnp.asarray(depth, dtype), jnp.asarray(mask, dtype)
    buffers = None if light_terms is None else _light_buffers(light_terms, light_buffers, hw, mask, channels)
    # buffers is None exactly when light_terms is: both tests are for mypy's sake.
    if light_terms is not None and buffers is not None and {"law", "fill"} & set(light_terms.used):
        image = apply_law(image, mask, light_terms.law, buffers, light_terms.law_strength, light_terms.fill)
    if light_terms is not None and buffers is not None and "transmission" in light_terms.used:
        # As HDRP's Lit shader: the transmitted light joins the diffuse lighting that the blur spreads.
        image = apply_transmission(image, mask, light_terms, buffers)
    out = _render(image, depth, mask, params, entry.name, tap_w, taps, strength, follow_surface)
    if light_terms is not None and buffers is not None and any(t in light_terms.used for t in AFTER_BLUR):
        out = apply_light_terms(out, depth, mask, params, light_terms, buffers)
    return out[..., 0] if squeeze else out
