"""How noisy a path-traced target is, from two independently seeded halves.

The target is the mean of two renders with half the samples each and different
seeds. Their difference is pure Monte Carlo noise: with per-pixel noise variance
``v`` in each half, the difference has variance ``2 v`` and the mean ``v / 2``,
a quarter of the difference's. So from the two halves alone:

* ``psnr_halves_db``: PSNR of one half against the other;
* ``noise_rms``: the per-pixel noise of the mean, ``rms(a - b) / 2``;
* ``noise_ceiling_db``: the PSNR a perfect, noise-free prediction would reach
  against the (noisy) mean, ``psnr_halves_db + 20 log10 2``. A fit cannot
  honestly score above it.

PSNR here is the one the estimator reports (:mod:`invsss.estimator.diagnostics`):
over the mask, with the target's range on the mask as the peak.
"""

from __future__ import annotations

import numpy as np

__all__ = ["half_render_noise"]


def half_render_noise(half_a: np.ndarray, half_b: np.ndarray, mask: np.ndarray) -> dict:
    """Noise statistics of the mean of two independent half renders (H, W, C), over ``mask`` (H, W).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> clean = np.linspace(0.0, 1.0, 64 * 64).reshape(64, 64, 1)
    >>> a, b = (clean + rng.normal(0.0, 0.02, clean.shape) for _ in range(2))
    >>> stats = half_render_noise(a, b, np.ones((64, 64)))
    >>> round(stats["noise_rms"], 3), round(stats["noise_ceiling_db"] - stats["psnr_halves_db"], 2)
    (0.014, 6.02)
    """
    on = mask > 0
    mean = 0.5 * (half_a + half_b)
    values = mean[on]
    peak = float(values.max() - values.min()) or 1.0
    mse_halves = float(np.mean((half_a - half_b)[on] ** 2))
    psnr_halves = 10.0 * np.log10(peak**2 / mse_halves) if mse_halves > 0 else float("inf")
    return {
        "psnr_halves_db": float(psnr_halves),
        "noise_ceiling_db": float(psnr_halves + 20.0 * np.log10(2.0)),
        "noise_rms": float(np.sqrt(mse_halves) / 2.0),
        "peak": peak,
    }
