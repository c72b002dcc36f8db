"""Light-aware terms (twin of :mod:`invsss.forward.light_terms`, docs/model.md, section 8).

The shifted image is sampled with :func:`kornia.geometry.transform.remap`
(bilinear, ``padding_mode="border"``, ``align_corners=True``) at the per-pixel
position ``(x - dx, y - dy)``, where the JAX core gathers four neighbours by hand.
"""

from __future__ import annotations

import torch
from kornia.geometry.transform import remap

from ..forward.light_terms import LAW_TRUST
from ..forward.transmission import TRANSMISSION_WRAP
from .stretch import stretch_factors

__all__ = ["propagation_offsets", "grazing_field", "incidence_field", "chandrasekhar_h", "law_trust", "reflectance_law",
           "law_source", "shift_image", "light_transport", "apply_light_terms", "apply_law", "burley_transmittance",
           "wrapped_back_lighting", "apply_transmission"]


def propagation_offsets(light: torch.Tensor) -> torch.Tensor:
    """(H, W, 3) camera-space unit vectors towards the light -> (H, W, 2) ``(-l_x, l_y)``."""
    return torch.stack([-light[..., 0], light[..., 1]], dim=-1)


def grazing_field(normal: torch.Tensor) -> torch.Tensor:
    """(H, W, 3) camera-space normals -> (H, W) ``1 - clip(n_z, 0, 1)``."""
    return 1.0 - normal[..., 2].clamp(0.0, 1.0)


def incidence_field(normal: torch.Tensor, light: torch.Tensor) -> torch.Tensor:
    """(H, W, 3) normals and light directions -> (H, W) ``1 - clip(n . l, 0, 1)``."""
    return 1.0 - (normal * light).sum(dim=-1).clamp(0.0, 1.0)


def chandrasekhar_h(x, albedo: torch.Tensor) -> torch.Tensor:
    """Hapke's ``H(x) = (1 + 2x) / (1 + 2x sqrt(1 - w))``; ``albedo`` (C,) or ()."""
    return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * (1.0 - albedo).clamp_min(1e-12).sqrt())


def law_trust(normal: torch.Tensor, light: torch.Tensor) -> torch.Tensor:
    """(H, W, 3) normals and light directions -> (H, W) ``clip(min(n_z, n . l) / LAW_TRUST, 0, 1)``."""
    cosines = torch.minimum(normal[..., 2], (normal * light).sum(dim=-1))
    return (cosines / LAW_TRUST).clamp(0.0, 1.0)


def reflectance_law(normal: torch.Tensor, light: torch.Tensor, albedo: torch.Tensor) -> torch.Tensor:
    """(H, W, 3) normals and light directions, albedo (C,) or () -> (H, W, C)
    ``1 + t (f_w(mu, mu0) / f_w(1, 1) - 1)`` with ``mu = clip(n_z, 0, 1)``,
    ``mu0 = clip(n . l, 0, 1)`` and ``t`` from :func:`law_trust`."""
    w = torch.atleast_1d(albedo)
    mu = normal[..., 2].clamp(0.0, 1.0)[..., None]
    mu0 = (normal * light).sum(dim=-1).clamp(0.0, 1.0)[..., None]
    head_on = chandrasekhar_h(1.0, w) ** 2 / 2.0
    ratio = chandrasekhar_h(mu, w) * chandrasekhar_h(mu0, w) / (mu + mu0).clamp_min(1e-6) / head_on
    return 1.0 + law_trust(normal, light)[..., None] * (ratio - 1.0)


def law_source(source: torch.Tensor, key: torch.Tensor, mask: torch.Tensor, gain: torch.Tensor,
               strength=1.0) -> torch.Tensor:
    """(H, W, C) ``S + m a K (gain - 1)``: one light's part ``K`` under the law with
    strength ``a``, the rest as it is."""
    return source + strength * mask[..., None] * key * (gain - 1.0)


def apply_law(image, mask, albedo, normal, light, key, strength=1.0, fill_light=None, fill=0.0) -> torch.Tensor:
    """Twin of :func:`invsss.forward.light_terms.apply_law` with the buffers as (H, W, 3) and (H, W, C)
    tensors: the key light's part ``key`` under the law with strength ``strength``, and the
    other lights' part ``image - key`` with direction ``fill_light`` under it with strength ``fill``."""
    out = law_source(image, key, mask, reflectance_law(normal, light, albedo), strength)
    if fill_light is None:
        return out
    return law_source(out, image - key, mask, reflectance_law(normal, fill_light, albedo), fill)


def shift_image(image: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """``image`` (H, W, C) read at ``(x - dx, y - dy)``; ``offset`` (H, W, 2) is ``(dx, dy)`` in pixels."""
    h, w, _ = image.shape
    cols = torch.arange(w, dtype=image.dtype, device=image.device)[None, :] - offset[..., 0]
    rows = torch.arange(h, dtype=image.dtype, device=image.device)[:, None] - offset[..., 1]
    sampled = remap(
        image.permute(2, 0, 1)[None], cols[None], rows[None],
        mode="bilinear", padding_mode="border", align_corners=True,
    )
    return sampled[0].permute(1, 2, 0)


def light_transport(blurred, mask, stretch, shift, grazing_gain, offsets=None, grazing=None,
                    incidence_gain=0.0, incidence=None) -> torch.Tensor:
    """The terms on a blurred (H, W, C) image; ``shift`` is kappa, ``grazing_gain`` is gamma,
    ``incidence_gain`` is beta."""
    out = blurred
    if offsets is not None:
        s_x, s_y = stretch
        out = shift_image(out, shift * torch.stack([s_x * offsets[..., 0], s_y * offsets[..., 1]], dim=-1))
    if grazing is not None:
        out = out * (1.0 + grazing_gain * grazing)[..., None]
    if incidence is not None:
        out = out * (1.0 + incidence_gain * incidence)[..., None]
    return blurred + mask[..., None] * (out - blurred)


def apply_light_terms(blurred, depth, mask, params, shift=0.0, grazing_gain=0.0, normal=None, light=None,
                      incidence_gain=0.0):
    """Twin of :func:`invsss.apply_light_terms` with the terms and buffers as plain arguments.

    ``params`` is an :class:`invsss.torch.SSSParams`; ``normal`` and ``light`` are
    (H, W, 3) tensors or None (the terms that need them off).
    """
    stretch = stretch_factors(depth, params.sss_level, params.correction, params.maxdd)
    offsets = None if light is None else propagation_offsets(light)
    field = None if normal is None else grazing_field(normal)
    incidence = None if normal is None or light is None else incidence_field(normal, light)
    return light_transport(blurred, mask, stretch, shift, grazing_gain, offsets, field, incidence_gain, incidence)


def burley_transmittance(x: torch.Tensor) -> torch.Tensor:
    """``(exp(-x) + 3 exp(-x / 3)) / 4`` elementwise: Burley's profile through ``x`` profile lengths."""
    return 0.25 * (torch.exp(-x) + 3.0 * torch.exp(-x / 3.0))


def wrapped_back_lighting(normal: torch.Tensor, light: torch.Tensor) -> torch.Tensor:
    """(H, W, 3) normals and light directions -> (H, W) ``clip((-n . l + W) / (1 + W)^2, 0, 1)``."""
    back = -(normal * light).sum(dim=-1)
    return ((back + TRANSMISSION_WRAP) / (1.0 + TRANSMISSION_WRAP) ** 2).clamp(0.0, 1.0)


def apply_transmission(image, mask, tint, scale, thickness, key_irradiance, normal, light) -> torch.Tensor:
    """Twin of :func:`invsss.forward.transmission.apply_transmission` with the terms and buffers as
    tensors: ``image`` and ``key_irradiance`` (H, W, C), ``mask`` and ``thickness`` (H, W),
    ``normal`` and ``light`` (H, W, 3), ``tint`` () or (C,), ``scale`` ()."""
    transmitted = burley_transmittance(scale * thickness) * wrapped_back_lighting(normal, light) * mask
    return image + torch.atleast_1d(tint) * key_irradiance * transmitted[..., None]
