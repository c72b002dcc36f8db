"""A skin mask made from the photographs themselves, for a pair without one.

A user with two photographs of a face (one in visible light, one in near-infrared, by
one camera) has no skin mask. :func:`make_skin_mask` makes one from the pair, by one of
two rules, and says which and how far to trust it:

- **dark background** (:func:`skin_mask_from_pair`, the rule for renders and for faces
  lit against the dark): what is bright in both photographs. It is used where it works:
  at least :data:`DARK_SHARE` of the pixels outside it are darker than :data:`DARK_LEVEL`
  of the skin's median in both photographs, it covers at most :data:`COVERAGE_LIMIT` of
  the frame and touches at most :data:`BORDER_LIMIT` of the frame's border.
- **face** (:mod:`invsss.io.face_mask`): otherwise (a studio portrait, a room), the face
  is found with scikit-image's frontal-face cascade and its skin told from what
  surrounds it by a model learned from its cheeks.
- **bright skin**: a face was found, and the bright region is within those limits and
  as much skin by that model as the face's outline (:data:`BRIGHT_SKIN_RELATIVE`): a
  face on a dim but not black surround, whose bright region follows its own edge.
- **no face found**: neither; the dark-background rule's mask, with a notice that it
  likely holds background.

The rule :func:`skin_mask_from_pair`:

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

Every mask, made or given, can be checked (:func:`mask_checks`, :func:`check_skin_mask`):
a notice (:class:`~invsss.validation.InputNotice`) when it covers more than
:data:`COVERAGE_LIMIT` of the frame, touches more than :data:`BORDER_LIMIT` of its
border, or less than :data:`SKIN_SHARE_LIMIT` of it passes the skin test of the face
found in the photographs. A blur fitted on such a mask is mostly the background's.

The result is 0/1 float32, written beside the fit as ``mask_used.png`` by ``invsss fit``
(docs/capture.md) so that it can be inspected, edited and given back with ``--mask``;
``params.json`` records the rule and the checks (``inputs.pairs[k].mask``).

Measured against the bundled pairs' own masks (``tests/io/test_skin_mask.py``,
``experiments/twowave_fit.py --masks``) and hand-drawn faces on two portraits
(``tests/io/test_photo_mask.py``): docs/capture.md, "A skin mask from the pair".
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..validation import InputNotice, InvalidInputError

if TYPE_CHECKING:  # face_mask (scikit-image) is imported only when a face is looked for
    from .face_mask import FaceBox

__all__ = [
    "BORDER_LIMIT",
    "BRIGHT_SKIN_RELATIVE",
    "CLOSING_RADIUS_PX",
    "COVERAGE_LIMIT",
    "DARK_LEVEL",
    "DARK_SHARE",
    "EDGE_FRACTION",
    "LOG_FLOOR",
    "RIM_PX",
    "SKIN_SHARE_LIMIT",
    "MadeMask",
    "border_share",
    "check_skin_mask",
    "has_dark_background",
    "make_skin_mask",
    "mask_checks",
    "mask_note",
    "skin_mask_from_pair",
]

#: A pixel is skin where it holds at least this share of the skin's local level: a
#: pixel half covered by a face is about half as bright as its neighbours inside.
EDGE_FRACTION = 0.5
#: Half-width (px) of the rim about the first foreground's edge that is decided again.
RIM_PX = 2
#: Added to the normalised grey before Otsu's threshold is taken on its logarithm.
LOG_FLOOR = 1e-3
#: Radius (px) of the closing that joins skin across dark stripes and pores.
CLOSING_RADIUS_PX = 2
#: The dark-background rule is used where at least DARK_SHARE of the pixels outside its
#: mask (3 px away) are darker than DARK_LEVEL times the median on the mask, in both
#: photographs. The bundled path-traced pairs and leeperrysmith have 0.87-1.00
#: (pt_face_ear_backlit_940 0.87, leeperrysmith 0.98, the rest 1.00; the scans on a dim
#: surround, fran_front and fran_turned, 0.00 and 0.06); skimage's astronaut 0.66 (green
#: and red) and 0.79 (colour), Grace Hopper 0.14, the camera man 0.26.
DARK_LEVEL = 0.02
DARK_SHARE = 0.8
#: A mask covering more than this share of the frame is likely more than skin (the
#: bundled renders' masks cover up to 0.61, the dark-background rule on the astronaut 0.77-0.83).
COVERAGE_LIMIT = 0.75
#: A mask touching more than this share of the frame's border is likely more than skin
#: (the bundled renders' masks touch up to 0.40).
BORDER_LIMIT = 0.5
#: A mask less than this share of which passes the skin test is mostly not skin.
SKIN_SHARE_LIMIT = 0.5
#: Where a face is found, the bright region is taken instead of the face's outline when
#: at least this share of it passes the skin test, relative to the outline's share: on
#: ``fran_front`` 0.96 (a scan on a dim surround); on the astronaut and Grace Hopper
#: 0.04-0.64 (backdrop, suit, sky).
BRIGHT_SKIN_RELATIVE = 0.9


def _grey(image, name: str) -> np.ndarray:
    x = np.asarray(image, np.float64)
    if x.ndim == 3:
        x = x.mean(axis=2)
    if x.ndim != 2 or min(x.shape) < 8:
        raise InvalidInputError(f"{name}: expected an image of at least 8x8 pixels, got shape {np.shape(image)}",
                                field=name)
    if not np.all(np.isfinite(x)):
        raise InvalidInputError(f"{name}: holds NaN or infinite values", field=name)
    top = float(np.percentile(x, 99.0))
    if top <= 0:
        raise InvalidInputError(f"{name}: is black (99th percentile <= 0); no skin to find", field=name)
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
    covered = np.maximum(uniform_filter(weight, 3, mode="nearest"), 1e-12)
    mean = uniform_filter(grey * weight, 3, mode="nearest") / covered
    rows, cols = distance_transform_edt(~interior, return_distances=False, return_indices=True)
    return mean[rows, cols]


def _check_one_grid(a: np.ndarray, b: np.ndarray) -> None:
    if a.shape != b.shape:
        raise InvalidInputError(
            f"near-infrared photograph: expected the visible photograph's size {a.shape}, got {b.shape} "
            "(the pair must come from one camera, one pixel grid)"
        )


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
    _check_one_grid(a, b)
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


class MadeMask(NamedTuple):
    """A mask :func:`make_skin_mask` made, the rule that made it and its checks.

    Attributes
    ----------
    mask : numpy.ndarray, shape (H, W), float32
        1 on skin, 0 elsewhere.
    method : str
        ``"dark background"``, ``"bright skin"``, ``"face"`` or ``"no face found"``
        (module text, :func:`make_skin_mask`).
    face : FaceBox or None
        The face's box (row, column, height, width in pixels) where one was found.
    checks : dict
        What :func:`mask_checks` measured.
    notices : tuple of str
        The notices given (each also warned as an :class:`~invsss.validation.InputNotice`).
    """

    mask: np.ndarray
    method: str
    face: FaceBox | None
    checks: dict
    notices: tuple

    def record(self) -> dict:
        """The rule, the face box, the checks and the notices, for ``params.json``."""
        face = None if self.face is None else [round(float(v), 1) for v in self.face]
        return {"method": self.method, "face": face, "checks": dict(self.checks), "notices": list(self.notices)}


def border_share(mask) -> float:
    """The share of the frame's border pixels (its outermost rows and columns) on the mask.

    Examples
    --------
    >>> import numpy as np
    >>> mask = np.zeros((10, 10)); mask[:, :5] = 1
    >>> border_share(mask)
    0.5
    """
    m = np.asarray(mask) > 0.5
    edge = np.concatenate([m[0], m[-1], m[1:-1, 0], m[1:-1, -1]])
    return float(edge.mean())


def has_dark_background(mask, visible, near_infrared) -> bool:
    """Whether the dark-background rule's ``mask`` is where that rule works (module text):
    what lies 3 px or more outside it is dark in both photographs (:data:`DARK_LEVEL`,
    :data:`DARK_SHARE`), and it neither covers most of the frame nor touches most of its border."""
    from scipy.ndimage import binary_dilation

    m = np.asarray(mask) > 0.5
    if not m.any() or m.mean() > COVERAGE_LIMIT or border_share(m) > BORDER_LIMIT:
        return False
    outside = ~binary_dilation(m, iterations=3)
    if not outside.any():
        return False
    for image in (visible, near_infrared):
        grey = np.asarray(image, np.float64)
        grey = grey.mean(axis=2) if grey.ndim == 3 else grey
        level = float(np.median(grey[m]))
        if level <= 0 or float(np.mean(grey[outside] < DARK_LEVEL * level)) < DARK_SHARE:
            return False
    return True


def mask_checks(mask, name: str, *, skin_share=None, skin_test: str = "not run",
                given: bool = False) -> tuple[dict, list[str]]:
    """The checks on a skin mask and the notices they give (none are warned here).

    Parameters
    ----------
    mask : array, shape (H, W)
        The mask (> 0.5 is on it).
    name : str
        How the notices name the mask (a file name).
    skin_share : float, optional
        The share of the mask that passes the skin test, if one was run.
    skin_test : str
        What that test was, or why none was run.
    given : bool
        The user gave the mask (``--mask``): the notices then do not advise giving one.

    Returns
    -------
    checks : dict
        ``coverage`` (share of the frame), ``border`` (share of the frame's border),
        ``skin_share`` (None without a test), ``skin_test``, and ``passed``.
    notices : list of str
        One line each: more than :data:`COVERAGE_LIMIT` of the frame, more than
        :data:`BORDER_LIMIT` of its border, less than :data:`SKIN_SHARE_LIMIT` skin.

    Examples
    --------
    >>> import numpy as np
    >>> checks, notices = mask_checks(np.ones((20, 20)), "mask.png")
    >>> checks["coverage"], checks["passed"], len(notices)
    (1.0, False, 2)
    >>> notices[0].split(";")[0]
    'mask.png: covers 100% of the frame (over 75%)'
    """
    m = np.asarray(mask) > 0.5
    coverage, border = round(float(m.mean()), 4), round(border_share(m), 4)
    skin_share = None if skin_share is None else round(float(skin_share), 4)
    notices = []
    advice = "it is used as given, so check that it is the skin you meant" if given else "look at it, or give --mask"
    tail = f"a blur fitted on it measures the background as much as the skin; {advice}"
    if coverage > COVERAGE_LIMIT:
        notices.append(f"{name}: covers {coverage:.0%} of the frame (over {COVERAGE_LIMIT:.0%}); it likely holds "
                       f"background, and {tail}")
    if border > BORDER_LIMIT:
        notices.append(f"{name}: touches {border:.0%} of the frame's border (over {BORDER_LIMIT:.0%}); a face "
                       f"seldom does, and {tail}")
    if skin_share is not None and skin_share < SKIN_SHARE_LIMIT:
        notices.append(f"{name}: only {skin_share:.0%} of it passes the skin test of the face found in the "
                       f"photographs (under {SKIN_SHARE_LIMIT:.0%}); it is mostly not skin, and {tail}")
    checks = {"coverage": coverage, "border": border, "skin_share": skin_share, "skin_test": skin_test,
              "passed": not notices}
    return checks, notices


def _skin_share(mask: np.ndarray, passes: np.ndarray) -> float:
    return float(np.mean(passes[mask])) if mask.any() else 0.0


def _warn(notices) -> None:
    for notice in notices:
        warnings.warn(notice, InputNotice, stacklevel=3)


def _made(mask, method, face, checks, notices) -> MadeMask:
    _warn(notices)
    return MadeMask(np.asarray(mask, bool).astype(np.float32), method, face, checks, tuple(notices))


def make_skin_mask(visible, near_infrared, name: str = "the mask made from the pair") -> MadeMask:
    """A skin mask of the face the two photographs show, by the rule that suits them
    (module text), with its checks; each notice is also warned (:class:`~invsss.validation.InputNotice`).

    Parameters
    ----------
    visible, near_infrared : array, shape (H, W) or (H, W, C)
        The two photographs, linear, on one pixel grid (one camera).
    name : str
        How the notices name the mask (``invsss fit``: ``mask_used.png``).

    Returns
    -------
    MadeMask
        Its ``method`` is ``"dark background"``, ``"bright skin"`` (a face was found and
        the bright region is as much its skin as the face's own outline: at least
        :data:`BRIGHT_SKIN_RELATIVE` of that share), ``"face"`` or ``"no face found"``.

    Raises
    ------
    InvalidInputError
        What :func:`skin_mask_from_pair` refuses (sizes, NaN, a black image), or no
        face found and nothing bright in both photographs.

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[0:64, 0:64]
    >>> disc = ((rows - 32) ** 2 + (cols - 30) ** 2 < 20 ** 2).astype(float)
    >>> made = make_skin_mask(disc * (0.6 + 0.1 * np.sin(cols / 3.0)), disc * 0.5)
    >>> made.method, int(made.mask.sum()) == int(disc.sum()), made.notices
    ('dark background', True, ())
    """
    from .face_mask import face_skin_mask, find_face

    _check_one_grid(_grey(visible, "visible photograph"), _grey(near_infrared, "near-infrared photograph"))
    try:
        bright = skin_mask_from_pair(visible, near_infrared) > 0.5
    except InvalidInputError:
        bright = None  # nothing bright in both (the images themselves were checked above)
    if bright is not None and has_dark_background(bright, visible, near_infrared):
        checks, notices = mask_checks(bright, name, skin_test="not run: a dark background")
        return _made(bright, "dark background", None, checks, notices)
    face = find_face(visible, near_infrared)
    if face is not None:
        mask, passes = face_skin_mask(visible, near_infrared, face)
        share = _skin_share(mask, passes)
        if mask.any():
            test = "the skin model of the face found"
            if (bright is not None and bright.mean() <= COVERAGE_LIMIT and border_share(bright) <= BORDER_LIMIT
                    and _skin_share(bright, passes) >= BRIGHT_SKIN_RELATIVE * share):
                checks, notices = mask_checks(bright, name, skin_share=_skin_share(bright, passes), skin_test=test)
                return _made(bright, "bright skin", face, checks, notices)
            checks, notices = mask_checks(mask, name, skin_share=share, skin_test=test)
            return _made(mask, "face", face, checks, notices)
    if bright is None:
        raise InvalidInputError("skin mask: no face found and no pixel bright in both photographs; give --mask")
    checks, notices = mask_checks(bright, name, skin_test="not run: no face found")
    notices.insert(0, f"{name}: no face found in the photographs and their background is not dark, so it is "
                      "the region bright in both, which on a photograph takes in background; look at it, "
                      "or give --mask")
    checks["passed"] = False
    return _made(bright, "no face found", None, checks, notices)


def check_skin_mask(mask, visible, near_infrared, name: str) -> dict:
    """The checks of :func:`mask_checks` on a given mask, with the skin test of the face
    the photographs show (none when no face is found); each notice is warned
    (:class:`~invsss.validation.InputNotice`).

    Returns
    -------
    dict
        ``checks`` (as :func:`mask_checks`), ``notices`` (list of str) and ``face``
        (its box, or None).
    """
    from .face_mask import find_face, skin_test

    m = np.asarray(mask) > 0.5
    face = find_face(visible, near_infrared)
    if face is None:
        checks, notices = mask_checks(m, name, skin_test="not run: no face found", given=True)
    else:
        checks, notices = mask_checks(m, name, skin_share=_skin_share(m, skin_test(visible, near_infrared, face)),
                                      skin_test="the skin model of the face found", given=True)
    _warn(notices)
    return {"face": None if face is None else [round(float(v), 1) for v in face], "checks": checks,
            "notices": notices}


def mask_note(record: dict) -> str | None:
    """One short line for the report figure from a mask's record (``checks`` and
    ``method``): what its checks found, or None when they passed.

    Examples
    --------
    >>> mask_note({"method": "face", "checks": {"coverage": 0.9, "border": 0.8, "skin_share": 0.1, "passed": False}})
    'mask: covers 90% of the frame, 80% of its border, 10% skin'
    """
    checks = record.get("checks") or {}
    if checks.get("passed", True):
        return None
    parts = [f"covers {checks['coverage']:.0%} of the frame" if checks.get("coverage", 0) > COVERAGE_LIMIT else "",
             f"{checks['border']:.0%} of its border" if checks.get("border", 0) > BORDER_LIMIT else "",
             f"{checks['skin_share']:.0%} skin" if checks.get("skin_share") is not None
             and checks["skin_share"] < SKIN_SHARE_LIMIT else ""]
    if record.get("method") == "no face found":
        parts.insert(0, "no face found")
    return "mask: " + ", ".join(p for p in parts if p)
