"""The face in a photograph and the skin around it: a skin mask for a pair that is not
a render on a dark background.

A studio portrait has a lit backdrop, hair, clothes and flags as bright as the face, so
the rule for renders (:func:`invsss.io.skin_mask.skin_mask_from_pair`: what is bright in
both photographs) takes in most of the frame. Here the face is found first and its skin
is then told from what surrounds it:

1. **The face** (:func:`find_face`): scikit-image's frontal-face cascade
   (``skimage.feature.Cascade`` with ``skimage.data.lbp_frontal_face_cascade_filename()``,
   multi-block LBP features trained by OpenCV) on each photograph as display-coded grey
   (its 99th percentile as white, the sRGB curve), at most :data:`DETECTION_SIZE` pixels
   on a side, the visible one first (the near-infrared one only when the visible shows
   no face). Of the detections the largest is the face; the boxes at least half its
   size whose centres lie inside it are its other detections, and the face box is
   their median.
2. **A skin model learned from that face** (:class:`SkinModel`): per pixel, the log
   level of both photographs together, the log ratio of the two photographs (two bands:
   skin is redder, and brighter at 940 nm, than most backgrounds), for a colour
   photograph its log red/green and blue/green ratios, and a texture (the log local
   contrast of the level at a scale of a hundredth of the face's width). Their mean and
   covariance come from an ellipse over the cheeks and nose (:data:`SAMPLE_ELLIPSE`),
   first trimmed to the pixels within 3 robust deviations (median, MAD) on every feature
   (an eye or a nostril in the ellipse); the level's spread is doubled, since shading
   darkens skin without changing what it is. A pixel's squared Mahalanobis distance
   ``d2`` to that model is its skin test.
3. **The outline** (:func:`face_skin_mask`): a marker-controlled watershed
   (``skimage.segmentation.watershed``) on the gradient of the features (each in units
   of its skin deviation). Skin seeds: pixels of :data:`INNER_ELLIPSE` with ``d2 <``
   :data:`SEED_D2`. Background seeds: everything outside :data:`FACE_ELLIPSE` (the
   region a face can occupy relative to its box: from a third of the box above it, for a
   high forehead, to 1.15 box heights below its top, the chin; 0.18 box widths beyond
   each side, for the ears), with the pixels inside it that are clearly not skin
   (``d2 >`` :data:`NOT_SKIN_D2`) and connected to that outside (hair, a backdrop; not
   an eye, which the face encloses). Below the mouth (:data:`LOWER_FROM`) skin pixels
   joined to the seeds are seeds too: the chin is smooth, and without them the
   background floods it up to the lips. The skin basin within the face's region, its
   part that holds most of the cheek ellipse, with its holes filled, is the mask.

Photographs larger than :data:`WORK_SIZE` on a side are worked on at a reduced size and
the mask brought back to the full one. The ellipses and thresholds were chosen on
``skimage.data.astronaut()`` only; docs/capture.md ("A skin mask from the pair") gives
the IoU measured on it and on a portrait not used to choose them.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from ..validation import InvalidInputError
from .colour import linear_to_srgb

__all__ = [
    "DETECTION_SIZE",
    "FACE_ELLIPSE",
    "INNER_ELLIPSE",
    "LOWER_FROM",
    "MIN_FACE_FRACTION",
    "NOT_SKIN_D2",
    "SAMPLE_ELLIPSE",
    "SEED_D2",
    "SKIN_QUANTILE",
    "WORK_SIZE",
    "FaceBox",
    "SkinModel",
    "detect_faces",
    "face_skin_mask",
    "find_face",
    "pair_features",
    "skin_test",
]

#: Longest side (px) of the grey image the face detector searches.
DETECTION_SIZE = 512
#: A detection narrower than this share of the frame's shorter side is not taken for the
#: face: a fit needs the face large in the frame, and the cascade's only detection on
#: ``skimage.data.camera()`` (a face in profile) is a 28 px patch of grass (5 %).
MIN_FACE_FRACTION = 0.1
#: Longest side (px) the skin model and the outline are worked out at.
WORK_SIZE = 1024
#: Ellipses relative to the face box, as (centre row, centre column, half height, half
#: width) in box heights and widths from its top left corner: the cheeks and nose the
#: skin model is learned on, the face's inner part where skin is seeded, and the region
#: a face can occupy.
SAMPLE_ELLIPSE = (0.55, 0.5, 0.2, 0.3)
INNER_ELLIPSE = (0.55, 0.5, 0.4, 0.4)
FACE_ELLIPSE = (0.4, 0.5, 0.75, 0.68)
#: Squared Mahalanobis distances to the skin model: below SEED_D2 a pixel of the inner
#: ellipse seeds skin; above NOT_SKIN_D2 a pixel is clearly not skin.
SEED_D2 = 9.0
NOT_SKIN_D2 = 36.0
#: Below this many box heights from the box's top (under the mouth, where a frontal face
#: has no hair), skin pixels joined to the seeds seed skin too.
LOWER_FROM = 0.8
#: The skin test's quantile of chi-square (:attr:`SkinModel.limit`).
SKIN_QUANTILE = 0.99
#: Floor on each feature's standard deviation in the skin model (log units): a band
#: ratio that is the same everywhere (one photograph and its blurred copy) is not a test.
FEATURE_FLOOR = 0.02
#: The level's deviation in the skin model is multiplied by this (shading).
LEVEL_SPREAD = 2.0
#: Added to values normalised by their 99th percentile before their logarithm is taken.
_EPS = 0.01


class FaceBox(NamedTuple):
    """A face's box in pixels: top row, left column, height and width."""

    row: float
    col: float
    height: float
    width: float

    def ellipse(self, shape, geometry) -> np.ndarray:
        """A boolean (H, W) ellipse given as (centre row, centre column, half height,
        half width) in box heights and widths from the box's top left corner."""
        rows, cols = np.ogrid[0:shape[0], 0:shape[1]]
        cr, cc, hr, hc = geometry
        return (((rows - self.row - cr * self.height) / (hr * self.height)) ** 2
                + ((cols - self.col - cc * self.width) / (hc * self.width)) ** 2) <= 1.0

    def scaled(self, factor: float) -> FaceBox:
        """The box on an image ``factor`` times the size."""
        return FaceBox(*(float(v) * factor for v in self))


def _grey(image) -> np.ndarray:
    x = np.asarray(image, np.float64)
    return x.mean(axis=2) if x.ndim == 3 else x


def _unit(x: np.ndarray) -> np.ndarray:
    """``x`` over its 99th percentile (over the whole image, every channel), >= 0."""
    top = float(np.percentile(_grey(x), 99.0))
    return np.clip(x / top, 0.0, None) if top > 0 else np.zeros_like(x)


@functools.lru_cache(maxsize=1)
def _cascade():
    from skimage.data import lbp_frontal_face_cascade_filename
    from skimage.feature import Cascade

    return Cascade(lbp_frontal_face_cascade_filename())


def detect_faces(image) -> list[FaceBox]:
    """Every frontal face scikit-image's LBP cascade finds in ``image``, largest first.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C)
        Linear values (a photograph decoded from sRGB, or a raw one); shown to the
        detector as display-coded grey, its 99th percentile as white.

    Returns
    -------
    list of FaceBox
        In the image's pixels; empty when none is found.

    Examples
    --------
    >>> import numpy as np
    >>> detect_faces(np.zeros((64, 64)))
    []
    """
    from skimage.transform import rescale

    grey = _grey(image)
    if grey.ndim != 2 or not np.all(np.isfinite(grey)):
        raise InvalidInputError(
            f"face detection: expected a finite (H, W) or (H, W, C) image, got shape {np.shape(image)}")
    shown = linear_to_srgb(np.clip(_unit(grey), 0.0, 1.0))
    factor = min(1.0, DETECTION_SIZE / max(shown.shape))
    if factor < 1.0:
        shown = rescale(shown, factor, anti_aliasing=True)
    if min(shown.shape) < 24:
        return []
    found = _cascade().detect_multi_scale(img=shown.astype(np.float32), scale_factor=1.2, step_ratio=1.0,
                                          min_size=(24, 24), max_size=shown.shape)
    boxes = [FaceBox(d["r"], d["c"], d["height"], d["width"]).scaled(1.0 / factor) for d in found]
    return sorted(boxes, key=lambda b: -b.height * b.width)


def find_face(visible, near_infrared) -> FaceBox | None:
    """The face the photographs show (module text, step 1).

    Parameters
    ----------
    visible, near_infrared : array, shape (H, W) or (H, W, C)
        The two photographs, linear, on one pixel grid.

    Returns
    -------
    FaceBox or None
        The median of the largest detection's group in the visible photograph, or in
        the near-infrared one when the visible shows none; detections narrower than
        :data:`MIN_FACE_FRACTION` of the frame's shorter side left out. None when
        neither photograph shows a frontal face.
    """
    least = MIN_FACE_FRACTION * min(np.shape(visible)[:2])
    boxes = [b for b in detect_faces(visible) if b.width >= least]
    boxes = boxes or [b for b in detect_faces(near_infrared) if b.width >= least]
    if not boxes:
        return None
    top = boxes[0]
    group = [b for b in boxes if b.height >= 0.5 * top.height
             and top.row <= b.row + b.height / 2 <= top.row + top.height
             and top.col <= b.col + b.width / 2 <= top.col + top.width]
    return FaceBox(*(float(v) for v in np.median(np.array(group), axis=0)))


def pair_features(visible, near_infrared, texture_px: float) -> tuple[np.ndarray, list[str]]:
    """The skin model's features per pixel (module text, step 2).

    Parameters
    ----------
    visible, near_infrared : array, shape (H, W) or (H, W, C)
        The two photographs, linear, on one pixel grid.
    texture_px : float
        The texture's scale and the features' smoothing, px.

    Returns
    -------
    features : numpy.ndarray, shape (H, W, K)
    names : list of str
        K names: level, band ratio, each colour photograph's red/green and
        blue/green, texture.
    """
    from scipy.ndimage import gaussian_filter

    vis, nir = _unit(np.asarray(visible, np.float64)), _unit(np.asarray(near_infrared, np.float64))
    a, b = _grey(vis), _grey(nir)
    features = [np.log(a + b + _EPS), np.log((b + _EPS) / (a + _EPS))]
    names = ["level", "band ratio"]
    for label, image in (("visible", vis), ("near-infrared", nir)):
        if image.ndim == 3 and image.shape[2] >= 3:
            green = image[..., 1] + _EPS
            features += [np.log((image[..., 0] + _EPS) / green), np.log((image[..., 2] + _EPS) / green)]
            names += [f"{label} red/green", f"{label} blue/green"]
    level = features[0]
    detail = level - gaussian_filter(level, texture_px)
    features.append(np.log(np.sqrt(gaussian_filter(detail ** 2, 2.0 * texture_px)) + _EPS))
    names.append("texture")
    stacked = np.stack(features, axis=-1)
    return gaussian_filter(stacked, (texture_px, texture_px, 0)), names


class SkinModel:
    """The skin of one face: the mean and covariance of :func:`pair_features` over its
    cheeks (module text, step 2).

    Attributes
    ----------
    mean : numpy.ndarray, shape (K,)
    covariance : numpy.ndarray, shape (K, K)
        With the level's deviation multiplied by :data:`LEVEL_SPREAD`.
    deviation : numpy.ndarray, shape (K,)
        Each feature's standard deviation on the skin (before the level's spread).
    names : list of str
    limit : float
        A pixel passes the skin test where its ``d2`` is at most this: the
        :data:`SKIN_QUANTILE` quantile of chi-square with K degrees of freedom, which
        ``d2`` follows on skin whose features are Gaussian.
    """

    def __init__(self, features: np.ndarray, names, sample: np.ndarray):
        x = features[sample]
        if len(x) < 2 * features.shape[-1] + 2:
            raise InvalidInputError("skin mask: the face is too small to learn its skin from; give --mask")
        median = np.median(x, axis=0)
        spread = 1.4826 * np.median(np.abs(x - median), axis=0) + 1e-3
        kept = x[np.all(np.abs(x - median) / spread < 3.0, axis=1)]
        kept = kept if len(kept) > 2 * x.shape[1] else x
        covariance = np.atleast_2d(np.cov(kept.T)) + np.diag(np.full(x.shape[1], FEATURE_FLOOR ** 2))
        self.names = list(names)
        self.mean = kept.mean(axis=0)
        self.deviation = np.sqrt(np.diag(covariance))
        stretch = np.ones(x.shape[1])
        stretch[0] = LEVEL_SPREAD
        self.covariance = covariance * np.outer(stretch, stretch)
        self._inverse = np.linalg.inv(self.covariance)
        from scipy.stats import chi2

        self.limit = float(chi2.ppf(SKIN_QUANTILE, x.shape[1]))

    def distance2(self, features: np.ndarray) -> np.ndarray:
        """Squared Mahalanobis distance of each pixel's features to the skin, (H, W)."""
        d = features - self.mean
        return np.einsum("...i,ij,...j->...", d, self._inverse, d)


def _work_scale(shape) -> float:
    return min(1.0, WORK_SIZE / max(shape[:2]))


def _resized(image, factor: float) -> np.ndarray:
    from skimage.transform import rescale

    x = np.asarray(image, np.float64)
    if factor >= 1.0:
        return x
    return rescale(x, factor, anti_aliasing=True, channel_axis=2 if x.ndim == 3 else None)


def _skin_distance(visible, near_infrared, face: FaceBox):
    """At the working size: the face box, the features, the skin model and each pixel's d2."""
    factor = _work_scale(np.shape(visible))
    box = face.scaled(factor)
    features, names = pair_features(_resized(visible, factor), _resized(near_infrared, factor),
                                    max(1.0, box.width / 100.0))
    model = SkinModel(features, names, box.ellipse(features.shape, SAMPLE_ELLIPSE))
    return factor, box, features, model, model.distance2(features)


def skin_test(visible, near_infrared, face: FaceBox) -> np.ndarray:
    """The pixels that pass the skin test of ``face`` (module text, step 2).

    Parameters
    ----------
    visible, near_infrared : array, shape (H, W) or (H, W, C)
        The two photographs, linear, on one pixel grid.
    face : FaceBox
        From :func:`find_face`.

    Returns
    -------
    numpy.ndarray, shape (H, W), bool
        True where the squared distance to the face's skin model is at most its
        :attr:`SkinModel.limit`.
    """
    from skimage.transform import resize

    factor, _box, _features, model, d2 = _skin_distance(visible, near_infrared, face)
    if factor < 1.0:
        d2 = resize(d2, np.shape(visible)[:2], order=1)
    return d2 <= model.limit


def face_skin_mask(visible, near_infrared, face: FaceBox) -> tuple[np.ndarray, np.ndarray]:
    """The skin of the face in ``face``'s box (module text, step 3).

    Parameters
    ----------
    visible, near_infrared : array, shape (H, W) or (H, W, C)
        The two photographs, linear, on one pixel grid.
    face : FaceBox
        From :func:`find_face`.

    Returns
    -------
    mask : numpy.ndarray, shape (H, W), bool
        One connected region without holes (all False if no skin was seeded).
    passes : numpy.ndarray, shape (H, W), bool
        The pixels that pass the face's skin test (:func:`skin_test`).
    """
    from scipy.ndimage import binary_fill_holes
    from skimage.filters import sobel
    from skimage.measure import label
    from skimage.segmentation import watershed
    from skimage.transform import resize

    factor, box, features, model, d2 = _skin_distance(visible, near_infrared, face)
    work = d2.shape
    sample, inner, region = (box.ellipse(work, e) for e in (SAMPLE_ELLIPSE, INNER_ELLIPSE, FACE_ELLIPSE))
    # Not skin and reaching the outside of the face's region: hair, a backdrop, clothes.
    outside = label(~region | (d2 > NOT_SKIN_D2), connectivity=1)
    reached = np.unique(outside[~region])
    markers = (np.isin(outside, reached[reached > 0]) & ~inner).astype(np.int32)
    markers[inner & (d2 < SEED_D2)] = 2
    # Below the mouth, skin joined to the seeds seeds too: otherwise the smooth chin is
    # flooded from the region's lower edge up to the lips' edges.
    below = np.arange(work[0])[:, None] >= box.row + LOWER_FROM * box.height
    joined = label(below & ((markers == 2) | (region & (d2 < SEED_D2) & (markers == 0))), connectivity=1)
    seeded = np.unique(joined[markers == 2])
    markers[np.isin(joined, seeded[seeded > 0])] = 2
    edges = np.sqrt(sum(sobel(features[..., k] / model.deviation[k]) ** 2 for k in range(features.shape[-1])))
    skin = label((watershed(edges, markers) == 2) & region, connectivity=1)
    overlap = np.bincount(skin[sample], minlength=skin.max() + 1)
    overlap[0] = 0
    mask = binary_fill_holes(skin == int(np.argmax(overlap))) if overlap.any() else np.zeros(work, bool)
    if factor < 1.0:
        mask = resize(mask.astype(np.float64), np.shape(visible)[:2], order=1) >= 0.5
        d2 = resize(d2, np.shape(visible)[:2], order=1)
    return mask, d2 <= model.limit
