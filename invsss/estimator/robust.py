"""Robust per-pixel weights by iterative reweighting (IRLS).

A robust loss ``sum rho(r)`` is minimised as a sequence of weighted least-squares
problems: solve, set each pixel's weight to ``u = rho'(r) / r`` at its current
residual, solve again. The weights are held fixed inside each solve, so the
variable projection and the Gauss-Newton covariance stay exactly those of a
weighted least-squares problem.

The scale ``delta`` of the loss is ``k`` robust standard deviations of the
residual (``1.4826 * median |r|`` over the mask), so the losses act on outliers
only:

``"pseudo-huber"`` (default, mild)
    ``rho = delta^2 (sqrt(1 + (r/delta)^2) - 1)``, ``u = 1 / sqrt(1 + (r/delta)^2)``,
    ``k = 3``: a Gaussian residual keeps a weight above 0.95 within two sigma.
``"cauchy"``
    ``rho = delta^2 / 2 log(1 + (r/delta)^2)``, ``u = 1 / (1 + (r/delta)^2)``,
    ``k = 2.385`` (95 % efficiency for Gaussian noise); rejects gross outliers.
``None``
    plain least squares.
"""

from __future__ import annotations

import numpy as np

from ..validation import InvalidInputError

__all__ = ["ROBUST_LOSSES", "check_robust", "robust_scale", "robust_weights", "robust_loss", "psi_and_slope"]

ROBUST_LOSSES = ("pseudo-huber", "cauchy")
_K = {"pseudo-huber": 3.0, "cauchy": 2.385}


def check_robust(robust):
    """``None`` or one of :data:`ROBUST_LOSSES` ("none" and False mean None)."""
    if robust in (None, False, "none"):
        return None
    if robust not in ROBUST_LOSSES:
        raise InvalidInputError(
            f"robust: expected one of {', '.join(ROBUST_LOSSES)} or None, got {robust!r}"
        )
    return robust


def robust_scale(residuals, masks, kind: str) -> float:
    """The loss's ``delta``: ``k`` times 1.4826 the median absolute masked residual
    (0 when the residual vanishes)."""
    pooled = np.concatenate([np.abs(r[m > 0]).ravel() for r, m in zip(residuals, masks)])
    sigma = 1.4826 * float(np.median(pooled))
    return _K[kind] * sigma if np.isfinite(sigma) else 0.0


def robust_weights(residuals, delta: float, kind: str) -> list[np.ndarray]:
    """Weights ``u = psi(r) / r`` in (0, 1] for each pair's residual image (H, W, C)."""
    if delta <= 0:
        return [np.ones_like(r) for r in residuals]
    out = []
    for r in residuals:
        x2 = (np.asarray(r) / delta) ** 2
        out.append(1.0 / np.sqrt(1.0 + x2) if kind == "pseudo-huber" else 1.0 / (1.0 + x2))
    return out


def robust_loss(residuals, masks, delta: float, kind: str) -> float:
    """``sum m rho(r)`` over each pair's residual image (H, W, C) and its per-pixel
    weight ``m`` ((H, W, C), or (H, W) for every channel) at the scale ``delta``:
    one objective on which fits reweighted from different points can be compared.

    Examples
    --------
    >>> r = np.array([[[0.0], [1.0]]]); m = np.ones_like(r)
    >>> round(robust_loss([r], [m], 1.0, "pseudo-huber"), 6)  # sqrt(2) - 1
    0.414214
    """
    total = 0.0
    for r, m in zip(residuals, masks):
        r, m = np.asarray(r), np.asarray(m)
        # A per-pixel weight would broadcast against the channel axis, not along it.
        m = m[..., None] if m.ndim == r.ndim - 1 else m
        x2 = (r / delta) ** 2 if delta > 0 else r**2
        scale = delta**2 if delta > 0 else 1.0
        rho = x2 / 2.0 if delta <= 0 else (np.sqrt(1.0 + x2) - 1.0 if kind == "pseudo-huber"
                                           else 0.5 * np.log1p(x2))
        total += float(np.sum(m * scale * rho))
    return total


def psi_and_slope(r, delta: float, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """``psi(r) = rho'(r)`` and ``psi'(r)``, for the robust covariance."""
    if delta <= 0:
        return r, np.ones_like(r)
    x2 = (r / delta) ** 2
    if kind == "pseudo-huber":
        u = 1.0 / np.sqrt(1.0 + x2)
        return u * r, u**3
    u = 1.0 / (1.0 + x2)
    return u * r, u * u * (1.0 - x2)
