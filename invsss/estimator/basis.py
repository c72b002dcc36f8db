"""The images a prediction is a linear combination of (the *basis* of the projection).

The prediction of target channel ``j`` of pair ``p`` is

    T_pj ~ r_pj * sum_i beta_ij * X_pi[..., j] + b_pj

where the basis images ``X_pi`` depend nonlinearly on the free parameters and
``beta``, ``b`` are eliminated by least squares (:mod:`.projection`). The basis is

* a model whose weights are linear (``sog``), with weights eliminated: the K
  blurred layers ``B_i`` (docs/model.md, section 5) in the profile's order, so
  ``beta_ij = a_j w_ij`` (gain times weight);
* otherwise the model's output, so ``beta_j = a_j`` is the gain.

Bilinear cases, and how they are made linear:

* Grey target, RGB source: the prediction ``sum_c g_c sum_i w_i B_ic`` (``g = a m``,
  gain times mix) is bilinear in ``g`` and ``w``; eliminating the products
  ``g_c w_i`` as 3K free numbers would fit a general matrix where the model has a
  rank-one one. Every pass treats the channels alike and is linear in the image,
  so blurring commutes with mixing: the source is mixed to grey first (the mix is
  a nonlinear unknown on the simplex, two numbers, so it cannot go negative) and
  the projection sees the layers of the grey image; ``beta = a w`` stays linear,
  and the blur costs a third.
* Several pairs with their own exposure: ``a_p w_i`` is bilinear across pairs.
  The gain of pair p relative to pair 0, ``r_p``, is a nonlinear unknown (one per
  pair and channel), ``beta = a_0 w`` is shared and linear, offsets stay per pair.
* RGB target: one weight column per channel, ``beta_ij = a_j w_ij``, linear.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from ..forward.models import get_model
from ..forward.pair import ImagePair
from ..forward.params import SSSParams
from ..forward.screen_space import LAYOUT_RENDERERS, sog_layers

__all__ = ["basis_images", "model_source"]


def model_source(pair: ImagePair, natural: dict) -> Float[Array, "H W Cb"]:
    """The image the model blurs: the source, mixed to grey when a mix is solved."""
    if "mix" in natural:
        return jnp.einsum("hwc,c->hw", pair.source, natural["mix"])[..., None]
    return pair.source


def basis_images(
    pair: ImagePair, natural: dict, model: str, tap_weights: Float[Array, " 7"], linear_weights: bool
) -> Float[Array, "nb H W Cb"]:
    """The basis images of one pair for the natural parameter values ``natural``.

    ``model`` is a name of :data:`invsss.forward.models.MODEL_NAMES`; its table entry
    says whether the weights are linear (then the basis is the blurred layers)
    and which layout renders it. ``tap_weights`` is ignored by the kernel layout.
    """
    entry = get_model(model)
    image = model_source(pair, natural)
    L, c, delta = natural["sss_level"], natural["correction"], natural["maxdd"]
    variances = natural["variances"]
    if entry.weights_role == "linear" and linear_weights:
        # The table only allows linear weights for the layered layout, whose
        # output is the weighted mean of these layers.
        layers, order = sog_layers(image, pair.depth, pair.mask, L, c, delta, variances, tap_weights)
        # Back to the profile's order, so coefficient i belongs to Gaussian i.
        return layers[jnp.argsort(order)]
    params = SSSParams(L, c, delta, natural["weights"], variances)
    out = LAYOUT_RENDERERS[entry.layout](image, pair.depth, pair.mask, params, tap_weights)
    return out[None]
