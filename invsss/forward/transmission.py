"""The ``transmission`` light term (docs/model.md, section 8): light from a key light
behind a thin part that crossed it, as HDRP adds it to the diffuse lighting before its
blur (its Lit shader's ``EvaluateTransmission`` and ``ComputeTransmittanceDisney``):

    S' = S + m tau T(k t) v(-n . l) E

with ``t`` the thickness (mm) the key light crosses, ``E`` the albedo times the key
light's unshadowed irradiance, ``T`` Burley's transmittance and ``v`` HDRP's wrapped
back-side cosine. :class:`~invsss.forward.light_terms.LightTerms` holds ``tau``
(``transmission``) and ``k`` (``thickness_scale``).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .light_buffers import LightBuffers
from .light_terms import LightTerms

__all__ = ["TRANSMISSION_WRAP", "burley_transmittance", "wrapped_back_lighting", "transmitted_source",
           "apply_transmission"]

#: HDRP's ``TRANSMISSION_WRAP_LIGHT``, ``cos(pi / 2 - pi / 12)``: the back side's
#: cosine is wrapped by 15 degrees, so that thin parts seen edge-on still pass light.
TRANSMISSION_WRAP = float(np.cos(np.pi / 2 - np.pi / 12))


def burley_transmittance(x):
    """``T(x) = (exp(-x) + 3 exp(-x / 3)) / 4``: the share of Burley's normalised profile
    that crosses a slab ``x`` profile lengths thick (1 at ``x = 0``).

    HDRP's ``ComputeTransmittanceDisney`` with its volume albedo's factor of a quarter
    taken in: the integral over the far side's plane of the profile at the 3D
    distance, ``int 2 pi r R(sqrt(r^2 + t^2)) dr`` with ``R`` Burley's ``(exp(-r/d) +
    exp(-r/(3d))) / (8 pi d r)`` and ``x = t / d``.
    """
    third = jnp.exp(-x / 3.0)
    return 0.25 * third * (third * third + 3.0)


def wrapped_back_lighting(normal: Float[Array, "H W 3"], light: Float[Array, "H W 3"]) -> Float[Array, "H W"]:
    """``clip((-n . l + W) / (1 + W)^2, 0, 1)``, ``W`` = :data:`TRANSMISSION_WRAP`: the
    cosine of the key light on the back side, wrapped (0 where the light meets the
    front within 75 degrees of the normal)."""
    back = -jnp.sum(normal * light, axis=-1)
    return jnp.clip((back + TRANSMISSION_WRAP) / (1.0 + TRANSMISSION_WRAP) ** 2, 0.0, 1.0)


def transmitted_source(source, mask, tint, scale, thickness, key_irradiance, back_lighting):
    """``S + m tau T(k t) v E``: the source the blur spreads under the ``transmission``
    term (``back_lighting`` is :func:`wrapped_back_lighting`). The traced core that
    :func:`apply_transmission` and the estimator share.

    Shapes: ``source`` and ``key_irradiance`` (H, W, C); ``mask``, ``thickness`` and
    ``back_lighting`` (H, W); ``tint`` () or (C,); ``scale`` ().
    """
    transmitted = burley_transmittance(scale * thickness) * back_lighting * mask
    return source + jnp.atleast_1d(tint) * key_irradiance * transmitted[..., None]


def apply_transmission(image, mask, terms: LightTerms, buffers: LightBuffers):
    """Add the ``transmission`` term's light to a source before :func:`invsss.render` blurs it.

    Parameters
    ----------
    image : array, shape (H, W, C)
        The source (Lambertian).
    mask : array, shape (H, W)
    terms : LightTerms
        Its ``transmission`` (the tint) and ``thickness_scale``.
    buffers : LightBuffers
        With ``thickness`` (H, W), ``key_irradiance`` (H, W, C), ``normal`` and ``light``.

    Returns
    -------
    array, shape (H, W, C)

    Examples
    --------
    >>> import numpy as np
    >>> from invsss.forward.light_terms import LightBuffers, LightTerms
    >>> from invsss.forward.transmission import apply_transmission
    >>> n = np.zeros((1, 2, 3)); n[..., 2] = 1.0          # facing the camera
    >>> l = -n                                            # the key light straight behind
    >>> buffers = LightBuffers(n, l, thickness=np.zeros((1, 2)), key_irradiance=np.ones((1, 2, 1)))
    >>> out = apply_transmission(np.zeros((1, 2, 1)), np.ones((1, 2)), LightTerms(transmission=0.5), buffers)
    >>> round(float(out[0, 0, 0]), 4)                     # 0.5 T(0) (1 + W) / (1 + W)^2
    0.3972
    """
    image = jnp.asarray(image)
    dtype = image.dtype
    thickness = jnp.asarray(buffers.thickness, dtype)
    if thickness.ndim == 3:
        thickness = thickness[..., 0]
    key_irradiance = jnp.asarray(buffers.key_irradiance, dtype)
    if key_irradiance.ndim == 2:
        key_irradiance = key_irradiance[..., None]
    back = wrapped_back_lighting(jnp.asarray(buffers.normal, dtype), jnp.asarray(buffers.light, dtype))
    return transmitted_source(image, jnp.asarray(mask, dtype), jnp.asarray(terms.transmission, dtype),
                              jnp.asarray(terms.thickness_scale, dtype), thickness, key_irradiance, back)
