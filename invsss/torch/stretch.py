"""Jimenez's depth stretch factors (twin of :mod:`invsss.forward.stretch`, docs/model.md, section 2)."""

from __future__ import annotations

import torch

__all__ = ["depth_slopes", "stretch_factors"]


def depth_slopes(depth: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(|dd/dx|, |dd/dy|)``, each (H, W), with ``numpy.gradient``'s stencil.

    :func:`torch.gradient` with unit spacing and ``edge_order=1`` is that stencil:
    central differences inside, one-sided on the border.
    """
    ddy, ddx = torch.gradient(depth, spacing=1.0, edge_order=1)
    return ddx.abs(), ddy.abs()


def stretch_factors(depth: torch.Tensor, sss_level, correction, maxdd) -> tuple[torch.Tensor, torch.Tensor]:
    """``(s_x, s_y)``, each (H, W): ``s = L / (d + c * min(|dd|, delta))`` pixels per scene unit.

    Examples
    --------
    >>> import torch
    >>> sx, sy = stretch_factors(torch.full((4, 4), 2.0), 10.0, 5.0, 0.1)
    >>> float(sx[0, 0])
    5.0
    """
    slope_x, slope_y = depth_slopes(depth)
    maxdd = torch.as_tensor(maxdd, dtype=depth.dtype, device=depth.device)
    s_x = sss_level / (depth + correction * torch.minimum(slope_x, maxdd))
    s_y = sss_level / (depth + correction * torch.minimum(slope_y, maxdd))
    return s_x, s_y
