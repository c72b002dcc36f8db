"""Scoring a render against its target: the photometric fit, loss, PSNR, SSIM.

A render uses the source's units; the target was taken by another camera with
its own exposure and, for a NIR photograph, one channel. As in the estimator
(docs/model.md, section 7) the render is first mapped to the target with the
least-squares gain and offset per target channel (for an RGB render and a grey
target: a mix of the three channels plus an offset), weighted by the mask.
The loss is then the mask-weighted mean squared residual over pixels and
channels, the estimator's loss without robust weights, so a render trial and a
fit trial report comparable numbers.
"""

from __future__ import annotations

import numpy as np

__all__ = ["score_render"]


def _hwc(x) -> np.ndarray:
    x = np.asarray(x, np.float64)
    return x[..., None] if x.ndim == 2 else x


def score_render(rendered, target, mask) -> dict:
    """Fit ``target ~ gain * rendered + offset`` on the mask and score the prediction.

    Parameters
    ----------
    rendered : array, shape (H, W, C)
    target : array, shape (H, W, C'), C' = C or 1
    mask : array, shape (H, W), weights in [0, 1]

    Returns
    -------
    dict
        ``loss``, ``psnr``, ``ssim`` (floats), ``gain``, ``offset`` (lists, one
        per target channel), ``channels_mix`` (3 numbers summing to 1 for an
        RGB render and a grey target, else None) and ``prediction`` (H, W, C').

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> rendered = rng.uniform(0, 1, (16, 16, 1))
    >>> score = score_render(rendered, 2.0 * rendered + 0.1, np.ones((16, 16)))
    >>> [round(v, 6) for v in (score["gain"][0], score["offset"][0], score["loss"])]
    [2.0, 0.1, 0.0]
    """
    from ..estimator.diagnostics import masked_psnr, masked_ssim

    rendered, target = _hwc(rendered), _hwc(target)
    weights = np.asarray(mask, np.float64)
    root = np.sqrt(weights).reshape(-1, 1)
    ones = np.ones((rendered.shape[0] * rendered.shape[1], 1))
    columns = rendered.reshape(-1, rendered.shape[2])
    prediction = np.empty_like(target)
    gain, offset, mix = [], [], None
    if target.shape[2] == 1 and rendered.shape[2] > 1:
        design = np.hstack([columns, ones])
        coef, *_ = np.linalg.lstsq(root * design, root[:, 0] * target.reshape(-1), rcond=None)
        prediction[..., 0] = (design @ coef).reshape(target.shape[:2])
        total = float(np.sum(coef[:-1]))
        gain, offset = [total], [float(coef[-1])]
        mix = (coef[:-1] / total).tolist() if total != 0 else coef[:-1].tolist()
    else:
        for c in range(target.shape[2]):
            design = np.hstack([columns[:, c : c + 1], ones])
            coef, *_ = np.linalg.lstsq(root * design, root[:, 0] * target[..., c].reshape(-1), rcond=None)
            prediction[..., c] = (design @ coef).reshape(target.shape[:2])
            gain.append(float(coef[0]))
            offset.append(float(coef[1]))
    squared = weights[..., None] * (target - prediction) ** 2
    loss = float(np.sum(squared) / (np.sum(weights) * target.shape[2]))
    return {
        "loss": loss,
        "psnr": masked_psnr(prediction, target, weights),
        "ssim": masked_ssim(prediction, target, weights),
        "gain": gain,
        "offset": offset,
        "channels_mix": mix,
        "prediction": prediction,
    }
