"""Measure a diffusion profile from two photographs (thesis 3.2.5 and 4.1).

The thesis (after Jensen et al. 2001) lights skin with a small focused spot of 940 nm
light, photographs it, photographs a Spectralon target under the same exposure, and
turns the skin's intensity falloff into a reflectance profile ``R(r)``:

1. Spectralon reference (4.1.1-4.1.2): its lit area must have no saturated pixel (the
   reference would be lost); its mean intensity there is the reference level, 244 of
   255 in the thesis.
2. Sample band (4.1.2, Figure 4.5): a rectangle starting at the centre of the lit
   spot and running away from it, 5 mm wide; pixels that are saturated or inside the
   directly lit area are left out (only multiple scattering is wanted).
3. Falloff (4.1.2): the thesis averages each column of the band into one sample.
4. Normalisation (4.1.2, Figure 4.6): divide by the Spectralon level times the optical
   filter factor that dimmed the Spectralon shot (10 in the thesis: 244 * 10 = 2440).
5. Function fitting (4.1.3): a sum of Gaussians, :func:`invsss.fit_sum_of_gaussians`
   (:meth:`MeasuredProfile.fit`).

Two choices the thesis leaves open are explicit here:

* ``averaging="radial"`` (default) averages the band's pixels by their true distance
  from the spot centre (one-pixel bins), which is an unbiased sample of a radially
  symmetric ``R(r)``. ``averaging="column"`` is the thesis's column average with the
  column's distance as ``r``: every column mixes radii ``sqrt(x^2 + y^2)`` over the
  band's width. A Gaussian keeps its variance under this average but its weight is
  multiplied by :func:`column_average_gain` (0.37 for 0.55 mm^2, 0.89 for 8.7 mm^2
  in a 5 mm band), so narrow Gaussians lose weight against broad ones. Use it to
  reproduce the thesis; a sum-of-Gaussians fit of column averages is corrected
  exactly by dividing each weight by that gain.
* The skin-to-Spectralon ratio is ``R(r) * spot area`` (the Spectralon shows the
  spot's irradiance, the skin the light scattered from the whole spot), so the
  diffusion profile in mm^-2 is the ratio divided by the spot's area. The thesis did
  not divide (its spot was "approximately 1 mm^2", 4.1.1); the default
  ``spot_area_mm2=1.0`` does the same, and :attr:`MeasuredProfile.lit_area_mm2`
  reports the lit area seen on the Spectralon so that it can be passed instead.

Images are linear intensities (raw counts or :func:`invsss.read_image` output); this is
array bookkeeping on concrete data, so it is NumPy, not JAX.
"""

from __future__ import annotations

import equinox as eqx
import numpy as np

from ..validation import InvalidInputError, check_image, positive_number
from .profile_fit import ProfileFit, fit_sum_of_gaussians

__all__ = ["DIRECTIONS", "AVERAGINGS", "MeasuredProfile", "measure_profile", "column_average_gain"]

#: Directions of the sample band from the spot centre (x is the column, y the row).
DIRECTIONS = {"right": (0.0, 1.0), "left": (0.0, -1.0), "down": (1.0, 0.0), "up": (-1.0, 0.0)}
#: How the band is reduced to a 1-D falloff.
AVERAGINGS = ("radial", "column")


class MeasuredProfile(eqx.Module):
    """A measured radial profile and what went into it.

    Attributes
    ----------
    r_mm : ndarray, shape (N,)
        Increasing distances from the spot centre, mm.
    reflectance : ndarray, shape (N,) or (N, C)
        ``R(r)``: skin intensity / (Spectralon level * filter factor) * Spectralon
        reflectance / spot area; (N, C) for a C-channel image.
    num_pixels : ndarray, shape (N,)
        Pixels averaged into each sample.
    spectralon_level : ndarray, shape () or (C,)
        Mean Spectralon intensity over its lit area.
    lit_area_mm2 : float
        Area of the lit spot on the Spectralon (pixels at >= ``lit_threshold`` of its peak).
    lit_radius_mm : float
        Distances below this were left out as directly lit.
    centre : (float, float)
        Spot centre (row, column) in the skin image, pixels.
    spot_area_mm2 : float or None
        The spot's area from its power: the reference's light at >= 5 % of its peak,
        summed, over its mean level on the lit area. Unlike ``lit_area_mm2`` it counts
        the partly lit pixels at the spot's edge (a spot a few pixels wide loses much
        of its area to them), so it is the area to divide by for an absolute ``R``.
    reflectance_stderr : ndarray like ``reflectance``, or None
        Standard error of each sample from its pixels' scatter about a straight line
        in ``r`` across the bin (so the profile's own slope over one pixel is not
        counted as noise): ``sqrt(SSR / (n - 2) / n)`` in the units of
        ``reflectance``; NaN where a bin has fewer than 3 pixels.
    """

    r_mm: np.ndarray
    reflectance: np.ndarray
    num_pixels: np.ndarray
    spectralon_level: np.ndarray
    lit_area_mm2: float = eqx.field(static=True)
    lit_radius_mm: float = eqx.field(static=True)
    centre: tuple = eqx.field(static=True)
    reflectance_stderr: np.ndarray | None = None
    spot_area_mm2: float | None = eqx.field(static=True, default=None)

    def fit(self, num_gaussians: int = 3, **kwargs) -> ProfileFit:
        """Sum-of-Gaussians fit of the samples (thesis 4.1.3); see :func:`fit_sum_of_gaussians`."""
        kwargs.setdefault("source", "measured profile")
        return fit_sum_of_gaussians(self.r_mm, self.reflectance, num_gaussians, **kwargs)


def column_average_gain(variances, band_width_mm: float):
    """What the thesis's column average does to each Gaussian of a profile.

    Averaging ``w G(v, sqrt(x^2 + y^2))`` over ``|y| <= h`` (``h`` half the band width)
    gives ``w * gain * G(v, x)`` with ``gain = sqrt(2 pi v) erf(h / sqrt(2 v)) / (2 h)``:
    the same variance, a weight scaled by ``gain``. Divide the weights of a fit of
    column averages by it to recover the profile. For a band of whole pixel rows,
    ``band_width_mm`` is the rows' full extent (rows times the pixel pitch).

    Parameters
    ----------
    variances : array, shape (K,)
        mm^2.
    band_width_mm : float
        Full width of the band across its direction, mm.

    Returns
    -------
    ndarray, shape (K,)

    Examples
    --------
    >>> round(float(column_average_gain([0.549], 5.0)[0]), 3)
    0.371
    """
    from scipy.special import erf

    v = np.asarray(variances, dtype=np.float64)
    half = 0.5 * positive_number(band_width_mm, "band_width_mm")
    if not np.all(np.isfinite(v)) or np.any(v <= 0):
        raise InvalidInputError("variances: expected finite values > 0")
    return np.sqrt(2.0 * np.pi * v) * erf(half / np.sqrt(2.0 * v)) / (2.0 * half)


def _as_channels(image):
    a = np.asarray(image, dtype=np.float64)
    return a[..., None] if a.ndim == 2 else a


def _spectralon_reference(spectralon, black_level, lit_threshold, saturation, mm_per_pixel,
                          name="spectralon_image"):
    # Step 1: the lit area is where the Spectralon is at least lit_threshold of its peak.
    brightness = spectralon.mean(axis=-1) - black_level
    peak = brightness.max()
    if not peak > 0:
        raise InvalidInputError(f"{name}: has no lit pixel (nothing above black_level)", field=name)
    lit = brightness >= lit_threshold * peak
    if saturation is not None:
        clipped = int(np.count_nonzero(np.any(spectralon[lit] >= saturation, axis=-1)))
        if clipped:
            raise InvalidInputError(
                f"{name}: {clipped} lit pixel(s) at the saturation level {saturation:g}; "
                "the reference needs an exposure without overexposure (thesis 4.1.2)",
                field=name,
            )
    level = spectralon[lit].mean(axis=0) - black_level
    rows, cols = np.nonzero(lit)
    # Half a pixel's diagonal past the farthest lit pixel centre covers that pixel.
    extent_px = np.max(np.hypot(rows - rows.mean(), cols - cols.mean())) + 0.5 * np.sqrt(2.0)
    power_area = brightness[brightness >= 0.05 * peak].sum() / float(np.mean(level)) * mm_per_pixel**2
    return level, lit.sum() * mm_per_pixel**2, extent_px * mm_per_pixel, power_area


def _spot_centre(skin):
    # Centroid of the skin's brightest region (>= half its peak): the lit spot.
    brightness = skin.mean(axis=-1)
    bright = brightness >= 0.5 * brightness.max()
    rows, cols = np.nonzero(bright)
    return float(rows.mean()), float(cols.mean())


# Over 80 lines, kept whole: the four steps of the thesis's measurement in their
# order (the reference, the band, one sample per distance bin, the normalisation),
# each on the same two images and numbered in the body.
def measure_profile(
    skin_image,
    spectralon_image,
    centre,
    mm_per_pixel: float,
    *,
    band_width_mm: float = 5.0,
    filter_factor: float = 10.0,
    direction: str = "right",
    averaging: str = "radial",
    saturation: float | None = 1.0,
    lit_radius_mm: float | None = None,
    max_radius_mm: float | None = None,
    spot_area_mm2: float = 1.0,
    spectralon_reflectance: float = 1.0,
    black_level: float = 0.0,
    lit_threshold: float = 0.5,
    names: tuple[str, str] = ("skin_image", "spectralon_image"),
) -> MeasuredProfile:
    """Diffusion profile from a point-lit skin photo and a Spectralon photo (thesis 4.1).

    Parameters
    ----------
    skin_image : array, shape (H, W) or (H, W, C)
        Linear intensities of skin lit by a small spot, floats (8-bit counts as floats
        with ``saturation=255`` work as well as [0, 1] data).
    spectralon_image : array, shape (H', W') or (H', W', C)
        The Spectralon target lit by the same spot, same exposure, taken through the
        optical filter of ``filter_factor``; any size, same channels.
    centre : (float, float) or None
        Spot centre (row, column) in ``skin_image``, pixels; None takes the centroid
        of the pixels at >= half the skin image's peak.
    mm_per_pixel : float
        Pixel pitch on the skin, mm.
    band_width_mm : float
        Width of the sample band across its direction (thesis: a 5 mm wide rectangle).
    filter_factor : float
        Light reduction of the optical filter used for the Spectralon shot (thesis: 10).
    direction : {"right", "left", "down", "up"}
        Where the band runs from the centre.
    averaging : {"radial", "column"}
        One-pixel bins of the true distance (default), or the thesis's per-column mean
        with the column's distance (biased by the band's width; see the module notes).
    saturation : float or None
        Intensity at or above which a pixel is overexposed (1.0 for [0, 1] images,
        255 for 8-bit counts); such skin pixels are left out, and such a Spectralon
        pixel in the lit area is an error. None: no check.
    lit_radius_mm : float or None
        Leave out distances below this as directly lit; None: the lit spot's extent on
        the Spectralon (farthest lit pixel from its centroid plus half a pixel diagonal).
    max_radius_mm : float or None
        Leave out distances above this; None: up to the image border.
    spot_area_mm2 : float
        Divide by this spot area; 1.0 reproduces the thesis, ``lit_area_mm2`` of a
        first call gives ``R`` in mm^-2.
    spectralon_reflectance : float
        Reflectance of the Spectralon (thesis: > 0.99; 1.0 reproduces its numbers).
    black_level : float
        Camera offset subtracted from both images first.
    lit_threshold : float
        Fraction of the Spectralon's peak that marks its lit area.
    names : (str, str)
        What error messages call the two images (``invsss profile`` gives their files).

    Returns
    -------
    MeasuredProfile
        ``r_mm``, ``reflectance`` and the reference values; ``.fit(K)`` fits Gaussians.

    Raises
    ------
    InvalidInputError
        Bad shapes or values, a saturated Spectralon, or a band with no usable pixel.

    Examples
    --------
    >>> import numpy as np
    >>> skin = np.full((32, 48), 24.4); skin[14:18, 4:8] = 255.0
    >>> spectralon = np.zeros((16, 16)); spectralon[6:10, 6:10] = 244.0
    >>> m = measure_profile(skin, spectralon, (15.5, 5.5), 0.25, saturation=255.0)
    >>> round(float(m.reflectance[0]), 6)  # 24.4 / (244 * 10)
    0.01
    """
    skin_name, spectralon_name = names
    check_image(skin_image, skin_name)
    check_image(spectralon_image, spectralon_name)
    skin = _as_channels(skin_image)
    spectralon = _as_channels(spectralon_image)
    if spectralon.shape[-1] != skin.shape[-1]:
        raise InvalidInputError(
            f"{spectralon_name}: expected {skin.shape[-1]} channel(s) like {skin_name}, "
            f"got {spectralon.shape[-1]}",
            field=spectralon_name,
        )
    mm_per_pixel = positive_number(mm_per_pixel, "mm_per_pixel")
    band_width_mm = positive_number(band_width_mm, "band_width_mm")
    filter_factor = positive_number(filter_factor, "filter_factor")
    spot_area_mm2 = positive_number(spot_area_mm2, "spot_area_mm2")
    spectralon_reflectance = positive_number(spectralon_reflectance, "spectralon_reflectance")
    if not 0 < float(lit_threshold) < 1:
        raise InvalidInputError(f"lit_threshold: expected a fraction in (0, 1), got {lit_threshold!r}")
    if direction not in DIRECTIONS:
        raise InvalidInputError(
            f"direction: expected one of {', '.join(DIRECTIONS)}, got {direction!r}"
        )
    if averaging not in AVERAGINGS:
        raise InvalidInputError(
            f"averaging: expected one of {', '.join(AVERAGINGS)}, got {averaging!r}"
        )
    if saturation is not None:
        saturation = positive_number(saturation, "saturation")
    if max_radius_mm is not None:
        max_radius_mm = positive_number(max_radius_mm, "max_radius_mm")
    if lit_radius_mm is not None:
        lit_radius_mm = float(lit_radius_mm)
        if not np.isfinite(lit_radius_mm) or lit_radius_mm < 0:
            raise InvalidInputError(f"lit_radius_mm: expected a finite number >= 0, got {lit_radius_mm!r}")
    try:
        black_level = float(black_level)
    except (TypeError, ValueError):
        black_level = float("nan")
    if not np.isfinite(black_level):
        raise InvalidInputError(f"black_level: expected a finite number, got {black_level!r}")

    # Step 1: the reference. Saturation is judged on raw values, before the black level.
    level, lit_area_mm2, lit_extent_mm, power_area_mm2 = _spectralon_reference(
        spectralon, black_level, lit_threshold, saturation, mm_per_pixel, spectralon_name
    )
    skin_clipped = (
        np.any(skin >= saturation, axis=-1) if saturation is not None else np.zeros(skin.shape[:2], bool)
    )
    skin = skin - black_level
    if lit_radius_mm is None:
        lit_radius_mm = lit_extent_mm

    h, w = skin.shape[:2]
    if centre is None:
        centre = _spot_centre(skin)
    try:
        cy, cx = (float(c) for c in centre)
    except (TypeError, ValueError):
        raise InvalidInputError(f"centre: expected (row, column) or None, got {centre!r}") from None
    if not (0 <= cy <= h - 1 and 0 <= cx <= w - 1):
        raise InvalidInputError(
            f"centre: ({cy:g}, {cx:g}) lies outside the {h}x{w} {skin_name}"
        )

    # Step 2: the band, in pixel units along and across its direction.
    dy, dx = DIRECTIONS[direction]
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    along = (rows - cy) * dy + (cols - cx) * dx
    across = (rows - cy) * dx - (cols - cx) * dy
    radius_px = np.hypot(along, across) if averaging == "radial" else along
    half_width_px = 0.5 * band_width_mm / mm_per_pixel
    usable = (along >= 0) & (np.abs(across) <= half_width_px) & ~skin_clipped
    usable &= radius_px * mm_per_pixel >= lit_radius_mm
    if max_radius_mm is not None:
        usable &= radius_px * mm_per_pixel <= max_radius_mm
    if not np.any(usable):
        raise InvalidInputError(
            f"{skin_name}: no usable pixel in the sample band (all saturated, directly lit, "
            "or outside the image); check centre, direction and lit_radius_mm",
            field=skin_name,
        )

    # Step 3: one sample per one-pixel bin of distance (per column in "column" mode).
    # floor(x + 0.5), not rint: rint rounds halves to even and would merge the columns
    # at 1.5 and 2.5 pixels from a centre between two pixels.
    bins = np.floor(radius_px[usable] + 0.5).astype(np.int64)
    counts = np.bincount(bins)
    present = counts > 0
    r_sum = np.bincount(bins, weights=radius_px[usable])[present]
    values = skin[usable]
    sums = np.stack(
        [np.bincount(bins, weights=values[:, c])[present] for c in range(values.shape[1])], axis=1
    )
    counts = counts[present]
    r_mm = r_sum / counts * mm_per_pixel
    mean_intensity = sums / counts[:, None]
    spread = _bin_stderr(bins, radius_px[usable], values, present, counts)

    # Step 4: thesis normalisation (244 * 10 = 2440), then the spot area (module notes).
    scale = spectralon_reflectance / (level * filter_factor * spot_area_mm2)
    reflectance = mean_intensity * scale
    single = np.ndim(skin_image) == 2
    return MeasuredProfile(
        r_mm=r_mm,
        reflectance=reflectance[:, 0] if single else reflectance,
        num_pixels=counts,
        spectralon_level=level[0] if single else level,
        lit_area_mm2=float(lit_area_mm2),
        spot_area_mm2=float(power_area_mm2),
        lit_radius_mm=float(lit_radius_mm),
        centre=(cy, cx),
        reflectance_stderr=(spread * scale)[:, 0] if single else spread * scale,
    )


def _bin_stderr(bins, radius, values, present, counts):
    """Standard error of each bin's mean about a line in ``r`` across the bin, (bins, C)."""
    index = np.searchsorted(np.nonzero(present)[0], bins)  # each pixel's sample
    n = counts.astype(np.float64)

    def total(weights):
        return np.bincount(index, weights=weights, minlength=n.size)

    dr = radius - (total(radius) / n)[index]
    srr = total(dr * dr)
    out = np.full((n.size, values.shape[1]), np.nan)
    enough = n >= 3
    for c in range(values.shape[1]):
        dv = values[:, c] - (total(values[:, c]) / n)[index]
        srv = total(dr * dv)
        slope_part = np.divide(srv**2, srr, out=np.zeros_like(srr), where=srr > 0)
        ssr = np.clip(total(dv * dv) - slope_part, 0.0, None)
        out[enough, c] = np.sqrt(ssr[enough] / (n[enough] - 2) / n[enough])
    return out
