"""Which samples of a measured profile a medium fit may trust, and why the others were left out.

Three limits, each reported with its radius:

* **the spot**: distances inside the lit spot (``lit_radius_mm`` of the measurement)
  hold directly lit skin and the spot's own size, not the profile;
* **the camera's resolution**: a one-pixel bin at ``r`` mixes radii ``r +- 0.5`` px,
  so samples nearer than ``min_radius_px`` pixels (3 by default: a third of the
  radius) are left out, and so are bins of fewer than 3 pixels, whose noise cannot
  be estimated;
* **the noise floor**: from the inside out, the samples are trusted until their
  signal-to-noise ratio ``R / stderr`` (median of three neighbours, so one noisy bin
  does not end the range) falls below ``min_snr``; everything beyond is dropped.

Concrete data only (NumPy).
"""

from __future__ import annotations

import equinox as eqx
import numpy as np

from ..validation import InvalidInputError

__all__ = ["TrustedRadii", "trusted_radii"]


class TrustedRadii(eqx.Module):
    """Trusted samples of a :class:`invsss.MeasuredProfile`, per channel.

    Attributes
    ----------
    mask : ndarray of bool, shape (N,) or (N, C)
        True for the samples a fit may use.
    r_min_mm, r_max_mm : ndarray, shape () or (C,)
        The trusted range (NaN for a channel with no trusted sample).
    reasons : tuple of str
        One line per limit: what it left out and from or up to which radius.
    """

    mask: np.ndarray
    r_min_mm: np.ndarray
    r_max_mm: np.ndarray
    reasons: tuple = eqx.field(static=True)


def _median3(x):
    padded = np.concatenate([x[:1], x, x[-1:]])
    return np.median(np.stack([padded[:-2], padded[1:-1], padded[2:]]), axis=0)


def trusted_radii(measured, mm_per_pixel: float, *, min_snr: float = 3.0,
                  min_radius_px: float = 3.0) -> TrustedRadii:
    """The samples of ``measured`` above the spot, the resolution and the noise floor.

    Parameters
    ----------
    measured : MeasuredProfile
        From :func:`invsss.measure_profile` (its ``reflectance_stderr`` is required).
    mm_per_pixel : float
        The pixel pitch the profile was measured at, mm.
    min_snr : float
        Noise floor: the smallest ``R / stderr`` trusted (> 0).
    min_radius_px : float
        Nearest trusted distance in pixels (>= 0).

    Returns
    -------
    TrustedRadii

    Raises
    ------
    InvalidInputError
        A profile without standard errors, or bad limits.
    """
    if getattr(measured, "reflectance_stderr", None) is None:
        raise InvalidInputError("measured: has no reflectance_stderr; measure it with measure_profile")
    for name, value, low in (("mm_per_pixel", mm_per_pixel, 0.0), ("min_snr", min_snr, 0.0)):
        if not (isinstance(value, (int, float)) and np.isfinite(value) and value > low):
            raise InvalidInputError(f"{name}: expected a finite number > {low:g}, got {value!r}")
    if not (isinstance(min_radius_px, (int, float)) and np.isfinite(min_radius_px) and min_radius_px >= 0):
        raise InvalidInputError(f"min_radius_px: expected a finite number >= 0, got {min_radius_px!r}")
    r = np.asarray(measured.r_mm, np.float64)
    y = np.asarray(measured.reflectance, np.float64)
    err = np.asarray(measured.reflectance_stderr, np.float64)
    single = y.ndim == 1
    y2, err2 = (y[:, None], err[:, None]) if single else (y, err)
    resolved = (r >= min_radius_px * mm_per_pixel) & (np.asarray(measured.num_pixels) >= 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.where(np.isfinite(err2) & (err2 > 0), y2 / err2, np.inf)
    snr = np.where(np.isfinite(err2), snr, 0.0)
    mask = np.zeros(y2.shape, bool)
    floors = []
    for c in range(y2.shape[1]):
        inside = np.nonzero(resolved)[0]
        smooth = _median3(snr[inside, c]) if inside.size else inside
        below = np.nonzero(smooth < min_snr)[0]
        keep = inside[: below[0]] if below.size else inside
        mask[keep, c] = True
        floors.append(r[inside[below[0]]] if below.size else np.nan)
    mask &= y2 > 0
    r_min = np.array([r[m].min() if m.any() else np.nan for m in mask.T])
    r_max = np.array([r[m].max() if m.any() else np.nan for m in mask.T])
    reasons = (
        f"spot: distances below {measured.lit_radius_mm:.2f} mm (the lit spot) were never sampled",
        f"resolution: below {min_radius_px * mm_per_pixel:.2f} mm ({min_radius_px:g} px) "
        f"and bins of fewer than 3 pixels left out ({_samples(int(np.sum(~resolved)))})",
        f"noise floor: R / stderr < {min_snr:g} "
        + ", ".join("nowhere" if np.isnan(f) else f"from {f:.2f} mm on" for f in floors)
        + (" (per channel)" if len(floors) > 1 else ""),
    )
    pick = (lambda a: a[..., 0]) if single else (lambda a: a)  # noqa: E731
    return TrustedRadii(pick(mask), pick(r_min), pick(r_max), reasons)


def _samples(count: int) -> str:
    return f"{count} sample" if count == 1 else f"{count} samples"
