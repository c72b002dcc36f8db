"""Radial diffusion profiles (twin of :mod:`invsss.forward.profiles`, docs/model.md, section 4)."""

from __future__ import annotations

import math

import torch

__all__ = ["gaussian", "sum_of_gaussians"]


def gaussian(variance, r):
    """Normalised 2D Gaussian ``G(v, r) = exp(-r^2 / (2 v)) / (2 pi v)``."""
    return torch.exp(-(r**2) / (2.0 * variance)) / (2.0 * math.pi * variance)


def sum_of_gaussians(r: torch.Tensor, weights: torch.Tensor, variances: torch.Tensor) -> torch.Tensor:
    """``R(r) = sum_i w_i G(v_i, r)``: shape (*N,) for weights (K,), (*N, C) for weights (K, C).

    Examples
    --------
    >>> import math, torch
    >>> float(sum_of_gaussians(torch.tensor(0.0), torch.tensor([1.0]), torch.tensor([1 / (2 * math.pi)])))
    1.0
    """
    g = gaussian(variances, r[..., None])  # (*N, K)
    if weights.ndim == 1:
        return (g * weights).sum(dim=-1)
    return torch.einsum("...k,kc->...c", g, weights)
