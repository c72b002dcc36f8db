"""A skin mask made from the photographs themselves, for a pair without one.

A user with two photographs of a face (one in visible light, one in near-infrared, by
one camera) has no skin mask. :func:`skin_mask_from_pair` makes one from the pair:

1. each photograph as grey (the mean of its channels), normalised by its 99th
   percentile;
2. a first foreground: pixels above Otsu's threshold of that grey's logarithm in *both*
   photographs (skin is lit in both; a background that is bright in one band only
   drops out), closed and hole-filled, its largest connected part;
3. the edge placed where a camera's pixel is half covered: within :data:`RIM_PX`
   pixels of the first foreground's edge, a pixel is skin where its value is at least
   :data:`EDGE_FRACTION` of the nearest interior pixel's (a 3x3 mean), averaged over
   the two photographs; the interior stays skin however dark (a shadow, a freckle);
4. clean-up (scikit-image): a closing with a disk of :data:`CLOSING_RADIUS_PX`
   (shadow stripes and pores stay skin), holes filled (eyes and nostrils inside the
   face are kept; the model only blurs, and a hole's edge is a strong edge to blur),
   the largest connected component.

The result is 0/1 float32, written beside the fit as ``mask_used.png`` by ``invsss fit``
(docs/capture.md) so that it can be inspected, edited and given back with ``--mask``.

Measured against the bundled pairs' own masks (``tests/test_skin_mask.py``,
``experiments/twowave_fit.py --masks``): docs/capture.md, "A skin mask from the pair".
"""

from __future__ import annotations

import numpy as np

from ..validation import InvalidInputError

__all__ = ["LOG_FLOOR", "EDGE_FRACTION", "RIM_PX", "CLOSING_RADIUS_PX", "skin_mask_from_pair"]

#: A pixel is skin where it holds at least this share of the skin's local level: a
#: pixel half covered by a face is about half as bright as its neighbours inside.
EDGE_FRACTION = 0.5
#: Half-width (px) of the rim about the first foreground's edge that is decided again.
RIM_PX = 2
#: Added to the normalised grey before Otsu's threshold is taken on its logarithm.
LOG_FLOOR = 1e-3
#: Radius (px) of the closing that joins skin across dark stripes and pores.
CLOSING_RADIUS_PX = 2


def _grey(image, name: str) -> np.ndarray:
    x = np.asarray(image, np.float64)
    if x.ndim == 3:
        x = x.mean(axis=2)
    if x.ndim != 2 or min(x.shape) < 8:
        raise InvalidInputError(f"{name}: expected an image of at least 8x8 pixels, got shape {np.shape(image)}")
    if not np.all(np.isfinite(x)):
        raise InvalidInputError(f"{name}: holds NaN or infinite values")
    top = float(np.percentile(x, 99.0))
    if top <= 0:
        raise InvalidInputError(f"{name}: is black (99th percentile <= 0); no skin to find")
    return np.clip(x / top, 0.0, None)


def _largest_component(mask: np.ndarray) -> np.ndarray:
    from skimage.measure import label

    labels = label(mask, connectivity=1)
    if labels.max() == 0:
        return mask
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return labels == int(np.argmax(sizes))


def _clean(mask: np.ndarray) -> np.ndarray:
    from scipy.ndimage import binary_fill_holes
    from skimage.morphology import closing, disk

    closed = closing(mask, disk(CLOSING_RADIUS_PX))
    return _largest_component(binary_fill_holes(closed))


def _inner_level(grey: np.ndarray, interior: np.ndarray) -> np.ndarray:
    """At each pixel, the brightness of the nearest interior pixel (a 3x3 mean over the
    interior, against noise): what the pixel would hold if the skin covered all of it."""
    from scipy.ndimage import distance_transform_edt, uniform_filter

    weight = interior.astype(np.float64)
    mean = uniform_filter(grey * weight, 3, mode="nearest") / np.maximum(uniform_filter(weight, 3, mode="nearest"), 1e-12)
    rows, cols = distance_transform_edt(~interior, return_distances=False, return_indices=True)
    return mean[rows, cols]


def skin_mask_from_pair(visible, near_infrared) -> np.ndarray:
    """A 0/1 skin mask of the face that both photographs show (see the module text).

    Parameters
    ----------
    visible, near_infrared : array, shape (H, W) or (H, W, C)
        The two photographs, linear, on one pixel grid (one camera).

    Returns
    -------
    numpy.ndarray, shape (H, W), float32
        1 on skin, 0 elsewhere: one connected region without holes.

    Raises
    ------
    InvalidInputError
        Images of different sizes, smaller than 8x8, black, or with NaN; or no
        foreground found in both.

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[0:64, 0:64]
    >>> disc = ((rows - 32) ** 2 + (cols - 30) ** 2 < 20 ** 2).astype(float)
    >>> visible = disc * (0.6 + 0.1 * np.sin(cols / 3.0)); nir = disc * 0.5
    >>> mask = skin_mask_from_pair(visible, nir)
    >>> int(mask.sum()) == int(disc.sum()), mask.dtype.name
    (True, 'float32')
    """
    from skimage.filters import threshold_otsu
    from skimage.morphology import dilation, disk, erosion

    a, b = _grey(visible, "visible photograph"), _grey(near_infrared, "near-infrared photograph")
    if a.shape != b.shape:
        raise InvalidInputError(
            f"near-infrared photograph: expected the visible photograph's size {a.shape}, got {b.shape} "
            "(the pair must come from one camera, one pixel grid)"
        )
    # On log brightness: a face half in shadow is still far brighter than the background,
    # while on a linear scale Otsu splits its lit side from its shaded one.
    log_a, log_b = np.log(a + LOG_FLOOR), np.log(b + LOG_FLOOR)
    first = (log_a > threshold_otsu(log_a)) & (log_b > threshold_otsu(log_b))
    if not first.any():
        raise InvalidInputError("skin mask: no pixel is bright in both photographs; give --mask")
    first = _clean(first)
    # Only the rim is decided again: inside, dark skin (a shadow, a freckle) is skin.
    interior = erosion(first, disk(RIM_PX))
    if not interior.any():
        interior = first
    rim = dilation(first, disk(RIM_PX)) & ~interior
    ratio = 0.5 * (a / np.maximum(_inner_level(a, interior), 1e-12) + b / np.maximum(_inner_level(b, interior), 1e-12))
    mask = _clean(interior | (rim & (ratio >= EDGE_FRACTION)))
    if not mask.any():
        raise InvalidInputError("skin mask: no skin found in the pair; give --mask")
    return mask.astype(np.float32)
