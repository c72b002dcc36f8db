"""The ``burley`` disk blur (twin of :mod:`invsss.forward.burley_screen_space`, docs/model.md, section 5).

Shares only the sample pattern's constants with the JAX code; the image is
read with :func:`kornia.geometry.transform.remap` (``grid_sample``, bilinear,
``padding_mode="border"``, ``align_corners=True``) at all samples at once,
where the JAX core gathers corners one sample at a time in a scan.
"""

from __future__ import annotations

import torch
from kornia.geometry.transform import remap

from ..forward.burley_screen_space import BURLEY_SAMPLES, check_burley_distances, sample_pattern

__all__ = ["render_burley"]


def _read(image: torch.Tensor, map_y: torch.Tensor, map_x: torch.Tensor) -> torch.Tensor:
    """``image`` (H, W, C) at real coordinates (H, W, N): (H, W, N, C), clamp-to-edge."""
    h, w, c = image.shape
    n = map_x.shape[-1]
    sampled = remap(
        image.permute(2, 0, 1)[None],
        map_x.reshape(1, h, w * n),
        map_y.reshape(1, h, w * n),
        mode="bilinear",
        padding_mode="border",
        align_corners=True,
    )  # (1, C, H, W*N)
    return sampled[0].reshape(c, h, w, n).permute(1, 2, 3, 0)


def render_burley(image, depth, mask, params, tap_w=None, samples: int = BURLEY_SAMPLES) -> torch.Tensor:
    """Burley's profile sampled over a disk: (H, W, C) from (H, W, C) ``image``, (H, W) depth and mask.

    ``params.variances`` are ``d_c^2`` (one, or one per channel); ``tap_w`` is not used.
    """
    h, w, c = image.shape
    check_burley_distances(params.variances, c)
    d = torch.sqrt(params.variances).expand(c)  # (C,)
    d_max = torch.amax(d)
    x_unit, cos_a, sin_a = (torch.as_tensor(a, dtype=image.dtype, device=image.device) for a in sample_pattern(samples))
    r = d_max * x_unit  # (N,) scene units
    radius_px = (params.sss_level / depth)[..., None] * r  # (H, W, N)
    ys = torch.arange(h, dtype=image.dtype, device=image.device)[:, None, None]
    xs = torch.arange(w, dtype=image.dtype, device=image.device)[None, :, None]
    stacked = torch.cat([image, mask[..., None], depth[..., None]], dim=-1)
    read = _read(stacked, ys + radius_px * sin_a, xs + radius_px * cos_a)  # (H, W, N, C + 2)
    value, on_skin, z = read[..., :c], read[..., c], read[..., c + 1]
    rho = torch.sqrt(r * r + (z - depth[..., None]) ** 2)[..., None]  # (H, W, N, 1)
    # R_c(rho) rho / pdf of the widest channel at r, up to a common factor.
    numerator = (torch.exp(-rho / d) + torch.exp(-rho / (3.0 * d))) / d
    denominator = ((torch.exp(-r / d_max) + torch.exp(-r / (3.0 * d_max))) / d_max)[:, None]
    weight = numerator / denominator * on_skin[..., None]
    total = (weight * value).sum(dim=2)
    weight_sum = weight.sum(dim=2)
    some = weight_sum > 0
    blurred = torch.where(some, total / torch.where(some, weight_sum, torch.ones_like(weight_sum)), image)
    return image + mask[..., None] * (blurred - image)
