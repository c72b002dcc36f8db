"""One directional pass (twin of :mod:`invsss.forward.passes`, docs/model.md, section 3).

Sampling is done by :func:`kornia.geometry.transform.remap`, i.e. ``grid_sample``
with bilinear interpolation, ``padding_mode="border"`` (clamp-to-edge) and
``align_corners=True`` (pixel centres at integer coordinates). The coordinate
across the pass is the pixel's own row (or column), so the bilinear weight across
it is 1 and the sample is linear interpolation along the row (or column), as the
JAX flat gather computes it.
"""

from __future__ import annotations

import torch
from kornia.geometry.transform import remap

from ..forward.passes import TAP_OFFSETS, TAP_WEIGHTS

__all__ = [
    "TAP_OFFSETS",
    "TAP_WEIGHTS",
    "tap_weights",
    "tap_spread",
    "sample_along",
    "directional_pass",
]


def tap_weights(spec="jimenez", dtype=None, device=None) -> torch.Tensor:
    """The 7 tap weights (7,) named by ``spec`` ("jimenez", "thesis") or given as numbers."""
    if isinstance(spec, str):
        if spec not in TAP_WEIGHTS:
            raise ValueError(
                f"tap_weights: expected one of {sorted(TAP_WEIGHTS)} or 7 numbers, got {spec!r}"
            )
        spec = TAP_WEIGHTS[spec]
    dtype = dtype or torch.get_default_dtype()
    if torch.is_tensor(spec):
        w = spec.to(dtype=dtype, device=device)
    else:
        w = torch.as_tensor(spec, dtype=dtype, device=device)
    if tuple(w.shape) != (7,):
        raise ValueError(f"tap_weights: expected 7 numbers, got shape {tuple(w.shape)}")
    return w


def tap_spread(weights: torch.Tensor) -> torch.Tensor:
    """``c_W = sqrt(sum_k W_k t_k^2)``: a footprint ``f`` blurs with std ``c_W * f`` pixels."""
    t = torch.as_tensor(TAP_OFFSETS, dtype=weights.dtype, device=weights.device)
    return torch.sqrt((weights * t**2).sum())


def sample_along(image: torch.Tensor, positions: torch.Tensor, axis: int) -> torch.Tensor:
    """Read ``image`` (H, W, C) at real ``positions`` (H, W, T) along rows (``axis=1``) or columns (``axis=0``).

    Returns (H, W, T, C): ``out[y, x, t] = I(y, positions[y, x, t])`` for ``axis=1``.
    Linear interpolation between the two nearest pixel centres, coordinates
    clamped to ``[0, n - 1]``; no gradient flows to a clamped coordinate.
    """
    h, w, c = image.shape
    taps = positions.shape[-1]
    if axis == 1:
        own = torch.arange(h, dtype=positions.dtype, device=positions.device)[:, None, None]
        map_x, map_y = positions, own.expand(h, w, taps)
    else:
        own = torch.arange(w, dtype=positions.dtype, device=positions.device)[None, :, None]
        map_x, map_y = own.expand(h, w, taps), positions
    # The T samples of pixel (y, x) become columns x*T .. x*T + T-1 of an (H, W*T) map.
    sampled = remap(
        image.permute(2, 0, 1)[None],
        map_x.reshape(1, h, w * taps),
        map_y.reshape(1, h, w * taps),
        mode="bilinear",
        padding_mode="border",
        align_corners=True,
    )  # (1, C, H, W*T)
    return sampled[0].reshape(c, h, w, taps).permute(1, 2, 3, 0)


def directional_pass(
    image: torch.Tensor, footprint: torch.Tensor, mask: torch.Tensor, weights: torch.Tensor, axis: int
) -> torch.Tensor:
    """``P(I; f)[y, x] = sum_k W_k I(y, x + t_k f[y, x])`` (H, W, C), blended by the mask (H, W).

    ``axis=1`` is the horizontal pass ``P_x``, ``axis=0`` the vertical ``P_y``;
    the result is ``I + m (P - I)``, ``I`` itself where ``m = 0``.
    """
    t = torch.as_tensor(TAP_OFFSETS, dtype=image.dtype, device=image.device)
    coord = torch.arange(image.shape[axis], dtype=image.dtype, device=image.device)
    base = coord[None, :] if axis == 1 else coord[:, None]
    positions = base[..., None] + footprint[..., None] * t
    blurred = torch.einsum("hwkc,k->hwc", sample_along(image, positions, axis), weights)
    return image + mask[..., None] * (blurred - image)
