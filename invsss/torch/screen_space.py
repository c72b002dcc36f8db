"""The screen-space models (twin of :mod:`invsss.forward.screen_space`, docs/model.md, section 5).

The ``render_*`` functions take (H, W, C) tensors of one dtype and a
:class:`~invsss.torch.SSSParams` in that dtype; :func:`render` is the checked
entry point that converts and validates.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from ..forward.models import MODEL_NAMES, get_model, resolve_tap_weights
from ..forward.pair import fill_background_depth
from ..forward.pass_plan import pass_plan
from ..validation import InvalidInputError, check_depth, check_image, check_mask
from .burley_screen_space import render_burley
from .params import SSSParams
from .passes import directional_pass, sample_along, tap_spread
from .passes import tap_weights as tap_weight_set
from .profiles import sum_of_gaussians
from .stretch import stretch_factors

__all__ = [
    "MODELS",
    "render",
    "render_sog",
    "render_thesis",
    "render_separable",
    "sog_layers",
    "separable_kernel",
]


#: The model names (the table is :mod:`invsss.forward.models`).
MODELS = MODEL_NAMES


def _taps(tap_weights, like: torch.Tensor) -> torch.Tensor:
    if isinstance(tap_weights, str):
        return tap_weight_set(tap_weights, like.dtype, like.device)
    return tap_weights


def sog_layers(image, depth, mask, sss_level, correction, maxdd, variances, tap_weights="jimenez"):
    """Layers ``B_1..B_K`` (K, H, W, C) of the ``sog`` model by increasing variance, and the sort order (K,).

    ``B_i = P_y(P_x(B_{i-1}; f_x,i); f_y,i)``, ``B_0 = I``, ``f_i = s sqrt(v_i - v_{i-1}) / c_W``.
    """
    w_taps = _taps(tap_weights, image)
    s_x, s_y = stretch_factors(depth, sss_level, correction, maxdd)
    # The plan sorts stably, as the JAX core does: tied variances keep their
    # order, which decides which of the two gets the zero-width pass.
    plan = pass_plan("layered", variances, tap_spread(w_taps), torch)
    layers = []
    layer = image
    for axis, width in zip(plan.axes, plan.widths):
        layer = directional_pass(layer, (s_x if axis == 1 else s_y) * width, mask, w_taps, axis=axis)
        if axis == 0:  # the vertical pass completes a layer
            layers.append(layer)
    return torch.stack(layers), plan.order


def render_sog(image, depth, mask, params: SSSParams, tap_weights="jimenez"):
    """``out = sum_i w_i B_i / sum_i w_i`` (H, W, C), per channel for (K, C) weights.

    Computed as ``I + sum_i (w_i / sum_j w_j) (B_i - I)``, as the JAX core does:
    where the mask is 0 every ``B_i`` is ``I`` bit-exactly, and so is the output
    (a weighted mean of equal numbers can round).
    """
    layers, order = sog_layers(
        image, depth, mask, params.sss_level, params.correction, params.maxdd, params.variances, tap_weights
    )
    w = params.weights[order]
    w = w.reshape(w.shape[0], -1)
    w = (w / w.sum(dim=0)).reshape(w.shape[0], 1, 1, -1)  # (K, 1, 1, 1 or C)
    return image + (w * (layers - image)).sum(dim=0)


def render_thesis(image, depth, mask, params: SSSParams, tap_weights="thesis"):
    """K horizontal passes then K vertical passes, ``f_i = s sqrt(v_i) / c_W``, in the given order."""
    w_taps = _taps(tap_weights, image)
    s_x, s_y = stretch_factors(depth, params.sss_level, params.correction, params.maxdd)
    plan = pass_plan("chained", params.variances, tap_spread(w_taps), torch)
    out = image
    for axis, width in zip(plan.axes, plan.widths):
        out = directional_pass(out, (s_x if axis == 1 else s_y) * width, mask, w_taps, axis=axis)
    return out


def separable_kernel(weights, variances, taps: int = 17, strength=1.0):
    """Jimenez 2015's kernel: offsets (N,) in scene units and weights (N, C), C = 1 or the weights' C.

    Offsets ``o = sign(u) u^2 / R``, ``u`` evenly spaced in ``[-R, R]`` (``R = 3`` when
    ``taps > 20``, else 2); each weight is the profile at ``|o|`` times half the
    distance to its neighbours, normalised per channel, then blended with the
    identity by ``strength`` (scalar or (C,)).
    """
    if taps < 3 or taps % 2 == 0:
        raise InvalidInputError(f"taps: expected an odd number >= 3, got {taps}")
    dtype = torch.promote_types(weights.dtype, variances.dtype)
    device = weights.device
    radius = 3.0 if taps > 20 else 2.0
    u = torch.linspace(-radius, radius, taps, dtype=dtype, device=device)
    offsets = torch.sign(u) * u**2 / radius
    gaps = torch.diff(offsets).abs()
    zero = offsets.new_zeros(1)
    area = 0.5 * (torch.cat([zero, gaps]) + torch.cat([gaps, zero]))
    profile = sum_of_gaussians(offsets.abs(), weights.to(dtype), variances.to(dtype)).reshape(taps, -1)
    kernel = area[:, None] * profile
    kernel = kernel / kernel.sum(dim=0)
    identity = torch.zeros(taps, 1, dtype=dtype, device=device)
    identity[taps // 2] = 1.0
    if torch.is_tensor(strength):
        strength = strength.to(dtype)
    else:
        strength = torch.as_tensor(strength, dtype=dtype, device=device)
    return offsets, strength * kernel + (1.0 - strength) * identity


def _separable_pass(image, depth, mask, offsets_px, kernel, follow_surface, axis):
    coord = torch.arange(image.shape[axis], dtype=image.dtype, device=image.device)
    base = coord[None, :] if axis == 1 else coord[:, None]
    positions = base[..., None] + offsets_px  # (H, W, N)
    samples = sample_along(image, positions, axis)  # (H, W, N, C)
    if not (isinstance(follow_surface, (int, float)) and follow_surface == 0):
        sampled_depth = sample_along(depth[..., None], positions, axis)[..., 0]
        pull = torch.clamp(follow_surface * (sampled_depth - depth[..., None]).abs(), 0.0, 1.0)
        samples = samples + pull[..., None] * (image[:, :, None, :] - samples)
    # kernel is (N, 1) or (N, C): broadcast over the channels either way.
    blurred = (samples * kernel).sum(dim=2)
    return image + mask[..., None] * (blurred - image)


def render_separable(image, depth, mask, params: SSSParams, taps: int = 17, strength=1.0, follow_surface=0.0):
    """One horizontal and one vertical pass (H, W, C) with the N-tap kernel at ``x + o L / d``."""
    offsets, kernel = separable_kernel(params.weights, params.variances, taps, strength)
    offsets = offsets.to(image.dtype)
    kernel = kernel.to(image.dtype)
    scale = params.sss_level / depth  # no correction term in this model
    offsets_px = scale[..., None] * offsets
    out = _separable_pass(image, depth, mask, offsets_px, kernel, follow_surface, axis=1)
    return _separable_pass(out, depth, mask, offsets_px, kernel, follow_surface, axis=0)


def _render_kernel(image, depth, mask, params, tap_w, taps=17, strength=1.0, follow_surface=0.0):
    # The kernel layout has no 7-tap passes: tap_w is None and not used.
    return render_separable(image, depth, mask, params, taps, strength, follow_surface)


#: The twin's renderer of each layout of :data:`invsss.forward.models.LAYOUTS`, called
#: as ``f(image, depth, mask, params, tap_w, **kernel_options)``.
LAYOUT_RENDERERS: dict[str, Callable[..., Any]] = {
    "layered": render_sog,
    "chained": render_thesis,
    "kernel": _render_kernel,
    "disk": render_burley,  # issue 34: invsss.torch.burley_screen_space
}


def _concrete(x):
    # The shared validators read values with NumPy; they never see the graph.
    return x.detach().cpu().numpy() if torch.is_tensor(x) else x


def _to(x, dtype, device):
    # .to keeps the autograd graph, so gradients reach the caller's tensors.
    return x.to(dtype=dtype, device=device) if torch.is_tensor(x) else torch.as_tensor(
        np.asarray(x), dtype=dtype, device=device
    )


def render(
    image,
    depth,
    mask,
    params: SSSParams,
    model: str = "sog",
    *,
    tap_weights=None,
    taps: int = 17,
    strength=1.0,
    follow_surface=0.0,
) -> torch.Tensor:
    """Apply screen-space subsurface scattering to ``image``; the twin of :func:`invsss.render`.

    Parameters
    ----------
    image : tensor or array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear radiance without scattering.
    depth : tensor or array, shape (H, W)
        Linear eye-space depth, > 0.
    mask : tensor or array, shape (H, W)
        1 on skin, 0 elsewhere; fractional values blend.
    params : invsss.torch.SSSParams
        Weights of shape (K, C) must have the image's C (or 1).
    model : {"sog", "thesis", "separable", "burley"}
        A name from :data:`invsss.forward.models.MODEL_NAMES`.
    tap_weights : {"jimenez", "thesis"} or 7 numbers, optional
        Default the model's ``default_tap_weights`` ("jimenez" for ``sog``,
        "thesis" for ``thesis``); unused by ``separable``.
    taps, strength, follow_surface
        ``separable`` only, as in :func:`invsss.render`.

    Returns
    -------
    tensor, same shape as ``image``
        In the image's dtype when it is a floating tensor, else torch's default
        dtype; every input is converted to it differentiably, so ``backward``
        reaches tensors passed in ``image``, ``params``, ``strength`` and
        ``follow_surface``.

    Examples
    --------
    >>> import torch, invsss.torch as itorch
    >>> image = torch.rand(8, 8, dtype=torch.float64)
    >>> depth = torch.full((8, 8), 500.0); mask = torch.ones(8, 8)
    >>> p = itorch.SSSParams(torch.tensor(800.0, requires_grad=True), 0.0, 1.0, [0.5, 0.5], [0.5, 2.0])
    >>> out = itorch.render(image, depth, mask, p)
    >>> out.shape, out.dtype
    (torch.Size([8, 8]), torch.float64)
    >>> out.sum().backward(); p.sss_level.grad is not None
    True
    """
    entry = get_model(model)
    check_image(_concrete(image))
    hw = tuple(np.shape(image)[:2])
    check_mask(_concrete(mask), hw)
    check_depth(_concrete(depth), hw, mask=_concrete(mask))
    # Renderer-style background depth (0 or inf off the mask), filled by the same
    # rule as the JAX model; a depth that needs no filling keeps its autograd graph.
    stored = _concrete(depth)
    filled = fill_background_depth(stored)
    if filled is not stored:
        depth = torch.as_tensor(np.asarray(filled))
    if not isinstance(params, SSSParams):
        raise InvalidInputError(f"params: expected invsss.torch.SSSParams, got {type(params).__name__}")
    params.check()
    channels = np.shape(image)[2] if len(np.shape(image)) == 3 else 1
    if params.weights.ndim == 2 and params.weights.shape[1] not in (1, channels):
        raise InvalidInputError(
            f"params.weights: expected one column per image channel ({channels}), "
            f"got shape {tuple(params.weights.shape)}"
        )
    tap_weights = resolve_tap_weights(entry, tap_weights)

    floating = torch.is_tensor(image) and image.is_floating_point()
    dtype = image.dtype if floating else torch.get_default_dtype()
    device = image.device if torch.is_tensor(image) else torch.device("cpu")
    image = _to(image, dtype, device)
    squeeze = image.ndim == 2
    if squeeze:
        image = image[..., None]
    tap_w = None
    if tap_weights is not None:
        try:
            tap_w = tap_weight_set(tap_weights, dtype, device)
        except ValueError as err:
            raise InvalidInputError(str(err)) from None
    depth, mask = _to(depth, dtype, device), _to(mask, dtype, device)
    params = params.to(dtype, device)
    options = {}
    if entry.layout == "kernel":
        if torch.is_tensor(strength):
            strength = strength.to(dtype=dtype, device=device)
        if torch.is_tensor(follow_surface):
            follow_surface = follow_surface.to(dtype=dtype, device=device)
        options = {"taps": taps, "strength": strength, "follow_surface": follow_surface}
    out = LAYOUT_RENDERERS[entry.layout](image, depth, mask, params, tap_w, **options)
    return out[..., 0] if squeeze else out
