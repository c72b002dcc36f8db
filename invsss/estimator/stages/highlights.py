"""Stage: a refit with the specular highlights left out (``highlights``)."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage

from ..core import Fit, FitCall
from ..inputs import prepare_pairs
from ..result import FitResult

__all__ = ["HIGHLIGHT_SIGMAS", "highlight_map", "without_highlights"]


#: A pixel is a highlight when its residual, smoothed over 1 px, is brighter than
#: the prediction by this many robust standard deviations of the smoothed residual.
HIGHLIGHT_SIGMAS = 3.0


def highlight_map(target, fitted, region) -> np.ndarray:
    """Pixels (H, W) of ``region`` where the target is markedly brighter than the fit."""
    residual = np.asarray(target, np.float64) - np.asarray(fitted, np.float64).reshape(np.shape(target))
    smooth = ndimage.gaussian_filter(residual.mean(axis=-1), 1.0)
    values = smooth[region]
    spread = 1.4826 * float(np.median(np.abs(values - np.median(values))))
    bright = region & (smooth - np.median(values) > HIGHLIGHT_SIGMAS * spread)
    return ndimage.binary_dilation(bright, iterations=1) & region


def without_highlights(inner: Fit) -> Fit:
    """The stage that refits with the specular highlights of a first fit's residual
    left out (``highlights``).

    The first fit is the inner stage's; the pixels where the target is markedly
    brighter than its prediction (:func:`highlight_map`) get a fit weight of 0, and
    the inner stage fits again on what is left. The result records what was left out.
    """

    def fit(call: FitCall) -> FitResult:
        first = inner(call)
        if not call.options.highlights or first.interrupted:
            return first
        pairs, counts, fractions = [], [], []
        for pair, fitted in zip(prepare_pairs(call.pairs), first.fitted):
            region = np.asarray(pair.residual_weight) > 0
            bright = highlight_map(pair.target, fitted, region)
            counts.append(int(bright.sum()))
            fractions.append(counts[-1] / max(float(region.sum()), 1.0))
            keep = np.where(bright, 0.0, 1.0 if pair.fit_weight is None else np.asarray(pair.fit_weight))
            # ImagePair keeps the NumPy weight as given; the field is annotated as a jax Array.
            pairs.append(dataclasses.replace(pair, fit_weight=keep if (keep * np.asarray(pair.mask)).any() else None))  # type: ignore[arg-type]
        record = {
            "method": f"residual of a first fit smoothed over 1 px, brighter than the prediction by "
                      f"{HIGHLIGHT_SIGMAS:g} robust standard deviations, dilated by 1 px",
            "excluded_pixels": counts,
            "fraction": fractions,
        }
        if not any(counts):
            return dataclasses.replace(first, highlights=record)
        second = inner(dataclasses.replace(call, pairs=pairs))
        return dataclasses.replace(second, highlights=record)

    return fit
