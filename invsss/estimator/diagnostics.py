"""Goodness of fit on the mask, and a check that the pair is aligned.

PSNR and SSIM compare the fitted prediction with the target where the mask is on
(scikit-image's metrics; SSIM's local map is averaged with the mask as weights).
The data range is the target's range on the mask.

A source/target pair that is misaligned by a pixel or more cannot be fitted by any
blur, and the fit then compensates with a wrong, wider blur. The prediction and
the target are registered by phase correlation
(:func:`skimage.registration.phase_cross_correlation`, to a tenth of a pixel) on
the mask's bounding box; a shift above :data:`MISALIGNMENT_PX` is a warning.
"""

from __future__ import annotations

import numpy as np
from skimage.metrics import structural_similarity
from skimage.registration import phase_cross_correlation

__all__ = ["MISALIGNMENT_PX", "masked_psnr", "masked_ssim", "misalignment"]

MISALIGNMENT_PX = 0.5


def _data_range(target, mask) -> float:
    on = target[mask > 0]
    span = float(on.max() - on.min())
    return span if span > 0 else 1.0


def masked_psnr(pred, target, mask) -> float:
    """PSNR in dB of ``pred`` against ``target`` (H, W, C) over the (weighted) mask."""
    m = mask[..., None] * np.ones_like(target)
    mse = float(np.sum(m * (pred - target) ** 2) / np.sum(m))
    peak = _data_range(target, mask)
    return float("inf") if mse == 0 else 10.0 * np.log10(peak**2 / mse)


def masked_ssim(pred, target, mask) -> float:
    """Mean SSIM over the (weighted) mask, (H, W, C) images."""
    win = min(7, *(s - (1 - s % 2) for s in target.shape[:2]))
    if win < 3:
        return float("nan")
    _, local = structural_similarity(
        target, pred, data_range=_data_range(target, mask), channel_axis=-1, full=True, win_size=win
    )
    m = mask[..., None] * np.ones_like(target)
    return float(np.sum(m * local) / np.sum(m))


def misalignment(pred, target, mask) -> tuple[float, float]:
    """The (dy, dx) shift in pixels that registers ``target`` onto ``pred``."""
    rows = np.flatnonzero(np.any(mask > 0, axis=1))
    cols = np.flatnonzero(np.any(mask > 0, axis=0))
    box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
    a = np.mean(pred[box], axis=-1)
    b = np.mean(target[box], axis=-1)
    if min(a.shape) < 4 or a.std() == 0 or b.std() == 0:
        return (0.0, 0.0)
    shift, _, _ = phase_cross_correlation(a - a.mean(), b - b.mean(), upsample_factor=10)
    return float(shift[0]), float(shift[1])
