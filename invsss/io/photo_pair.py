"""A pair of photographs without a 3D model: one distance instead of a depth map, and a
skin mask made from the pair when none is given.

The pair most users can make is two photographs of one face by one camera, once in
visible light and once in near-infrared (docs/capture.md, "Two photographs, no 3D
model"). The visible photograph is the *source*: it is already blurred by visible
light's scattering, so the fit measures the near-infrared blur *over* the visible one.
Without a face scan there is no depth map; ``--distance MM`` gives one eye depth for the
whole face (:func:`constant_depth`). Then the stretch ``L / (d + c min(|dd|, maxdd))`` is
``L / d`` everywhere: ``correction`` and ``maxdd`` change nothing in the image, so the fit
holds them (:data:`HELD_WITH_CONSTANT_DEPTH`, or values given with ``--fix``) and
``params.json`` says so under ``inputs.held``; only ``sss_level / distance`` (the blur
in pixels) is measured.

:func:`load_photo_pair` reads such a pair as :func:`invsss.load_pair` reads a full one
(the same image decoding and grey handling), with the depth and mask optional.
"""

from __future__ import annotations

import math
import numbers
import os
import warnings

import numpy as np

from ..forward.pair import ImagePair
from ..validation import InputNotice, InvalidInputError
from .depth import read_depth
from .images import finish_pair, load_pair, read_colour_pair
from .masks import read_mask
from .skin_mask import check_skin_mask, make_skin_mask, mask_note

__all__ = [
    "HELD_WITH_CONSTANT_DEPTH",
    "MASK_FILE",
    "PLAUSIBLE_DISTANCE_MM",
    "PhotoInputs",
    "check_depth_level",
    "check_distance",
    "check_photo_arguments",
    "constant_depth",
    "constant_depth_pair",
    "load_photo_pair",
    "photo_inputs",
]

#: The values ``correction`` and ``maxdd`` are held at on a constant depth, unless given
#: with ``fix``: no correction (the pair cannot measure one, and a renderer given 0
#: blurs by ``sss_level / depth`` alone), and a ``maxdd`` that then has no effect.
HELD_WITH_CONSTANT_DEPTH = {"correction": 0.0, "maxdd": 1.0}

#: The file ``invsss fit`` writes the mask it made into, beside the result.
MASK_FILE = "mask_used.png"

#: The distances (mm) a face is photographed from; :func:`check_distance` notes one outside.
PLAUSIBLE_DISTANCE_MM = (100.0, 5000.0)

_HELD_REASON = (
    "constant depth (--distance): no depth slope anywhere, so {name} changes nothing in the "
    "image and the pair cannot determine it; held at {value:g}"
)


def check_distance(distance_mm, name: str = "distance", *, notice: bool = True) -> float:
    """``distance_mm`` as a float, or a one-line error unless it is finite and > 0.

    A distance outside :data:`PLAUSIBLE_DISTANCE_MM` (100-5000 mm) is used, with an
    :class:`~invsss.validation.InputNotice` naming it (unless ``notice`` is False): it
    is more likely in another unit than a face's distance, and ``sss_level`` scales with it.

    Examples
    --------
    >>> check_distance(600)
    600.0
    >>> check_distance(-5.0)
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: distance: expected the face's distance from the camera in mm, a finite number > 0, got -5.0
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_distance(0.6)
    0.6
    >>> print(caught[0].message)
    distance: 0.6 mm is outside 100-5000 mm, where a face is photographed from; used as given, but the fitted sss_level scales with it (is it in mm?)
    """  # noqa: E501
    ok = isinstance(distance_mm, numbers.Real) and not isinstance(distance_mm, bool)
    if not ok or not math.isfinite(distance_mm) or distance_mm <= 0:
        raise InvalidInputError(
            f"{name}: expected the face's distance from the camera in mm, a finite number > 0, got {distance_mm!r}",
            field=name,
        )
    low, high = PLAUSIBLE_DISTANCE_MM
    if notice and not low <= distance_mm <= high:
        warnings.warn(
            f"{name}: {distance_mm:g} mm is outside {low:g}-{high:g} mm, where a face is photographed from; "
            "used as given, but the fitted sss_level scales with it (is it in mm?)",
            InputNotice, stacklevel=2,
        )
    return float(distance_mm)


def check_depth_level(depth, mask, mm_per_unit: float, name: str) -> float | None:
    """The skin's median depth in mm, with an :class:`~invsss.validation.InputNotice`
    when it lies outside :data:`PLAUSIBLE_DISTANCE_MM`, as :func:`check_distance` does
    for a distance; None where the mask has no pixel.

    A depth map is checked for NaN and for values <= 0 when it is read; a file that is
    not the depth at all (a photograph given as ``--depth``) or a depth in another
    unit than ``--depth-unit`` passes those checks, and the fitted ``sss_level``
    scales with it.

    Examples
    --------
    >>> import warnings
    >>> depth, mask = np.full((4, 4), 0.12), np.ones((4, 4))
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_depth_level(depth, mask, 1.0, "--depth target.exr")
    0.12
    >>> print(caught[0].message)
    --depth target.exr: the skin's median depth is 0.12 mm, outside 100-5000 mm, where a face is photographed from; used as given, but the fitted sss_level scales with it (is it a depth map, and in --depth-unit?)
    """  # noqa: E501
    on = np.asarray(mask) > 0
    if not on.any():
        return None
    median_mm = float(np.median(np.asarray(depth, np.float64)[on])) * mm_per_unit
    low, high = PLAUSIBLE_DISTANCE_MM
    if not low <= median_mm <= high:
        warnings.warn(
            f"{name}: the skin's median depth is {median_mm:.3g} mm, outside {low:g}-{high:g} mm, where a face is "
            "photographed from; used as given, but the fitted sss_level scales with it (is it a depth map, and "
            "in --depth-unit?)",
            InputNotice, stacklevel=2,
        )
    return median_mm


def constant_depth(shape, distance_mm) -> np.ndarray:
    """A depth map of one eye depth: ``distance_mm`` everywhere, float32 (H, W).

    Examples
    --------
    >>> constant_depth((2, 3), 600)
    array([[600., 600., 600.],
           [600., 600., 600.]], dtype=float32)
    """
    return np.full(tuple(shape)[:2], check_distance(distance_mm), np.float32)


def constant_depth_pair(source, target, distance_mm, mask=None) -> ImagePair:
    """An :class:`~invsss.ImagePair` whose depth is ``distance_mm`` on every pixel.

    Fit it with ``fix=HELD_WITH_CONSTANT_DEPTH`` (or other values for ``correction`` and
    ``maxdd``): on a constant depth they have no effect, and the fit measures
    ``sss_level / distance_mm``.

    Parameters
    ----------
    source, target : array, shape (H, W) or (H, W, C)
        The visible and the near-infrared photograph (or a render and a photograph).
    distance_mm : float > 0
        The face's distance from the camera, mm (along the optical axis).
    mask : array, shape (H, W), optional
        The skin mask; None makes one from the pair (:func:`invsss.io.skin_mask.make_skin_mask`,
        which warns when the mask it made is likely not skin only).

    Examples
    --------
    >>> import numpy as np
    >>> from invsss.io.photo_pair import HELD_WITH_CONSTANT_DEPTH, constant_depth_pair
    >>> visible = np.zeros((16, 16)); visible[3:13, 4:12] = 0.6
    >>> pair = constant_depth_pair(visible, 0.8 * visible, 600.0)
    >>> float(pair.depth.min()), float(pair.depth.max()), int(pair.mask.sum())
    (600.0, 600.0, 80)

    Then ``invsss.fit_pairs([pair], fix=HELD_WITH_CONSTANT_DEPTH)`` (as
    ``tests/cli/test_photo_pair.py`` does) measures ``sss_level / 600``.
    """
    source = np.asarray(source)
    if mask is None:
        mask = make_skin_mask(source, target).mask
    depth = constant_depth(np.shape(source), distance_mm)
    return ImagePair(source, np.asarray(target), depth, np.asarray(mask))  # type: ignore[arg-type]  # the fields' converters take array-likes


def load_photo_pair(
    source, target, *, depth=None, distance_mm=None, mask=None, depth_scale: float = 1.0, linear_codes: bool = False,
    mask_name: str = "the mask made from the pair",
):
    """Read a pair whose depth may be one distance and whose mask may be missing.

    With ``depth`` and ``mask`` both files this is :func:`invsss.load_pair`. Otherwise
    the images are read and decoded as there (sRGB for 8-bit codes unless
    ``linear_codes``; a grey stored as RGB becomes one channel), the depth is
    ``distance_mm`` everywhere, and the mask, if not given, is made from the two
    images (:func:`~invsss.io.skin_mask.make_skin_mask`; its notices name it ``mask_name``).

    Returns
    -------
    pair : ImagePair
    made : MadeMask or None
        The mask made from the pair, with its rule and checks
        (:class:`~invsss.io.skin_mask.MadeMask`); None when the mask was given.

    Raises
    ------
    InvalidInputError
        Neither or both of ``depth`` and ``distance_mm``, a bad distance, and
        everything :func:`invsss.load_pair` refuses.
    """
    if (depth is None) == (distance_mm is None):
        raise InvalidInputError(
            "depth: give either a depth map (--depth FILE) or one distance (--distance MM), "
            + ("not both" if depth is not None else "got neither")
        )
    if distance_mm is not None:
        check_distance(distance_mm, notice=False)  # constant_depth below notes an odd one
    if depth is not None and mask is not None:
        return load_pair(source, target, depth, mask, depth_scale=depth_scale, linear_codes=linear_codes), None
    source_image, target_image = read_colour_pair(source, target, linear_codes)
    depth_map = read_depth(depth, scale=depth_scale) if depth is not None else constant_depth(
        source_image.shape, distance_mm)
    made = None
    if mask is None:
        if source_image.shape[:2] != target_image.shape[:2]:
            raise InvalidInputError(
                f"{os.fspath(target)}: expected the source's size {source_image.shape[:2]}, got "
                f"{target_image.shape[:2]}"
            )
        made = make_skin_mask(source_image, target_image, mask_name)
        mask_map = made.mask
    else:
        mask_map = read_mask(mask)
    names = {"source": os.fspath(source), "target": os.fspath(target),
             "depth": os.fspath(depth) if depth is not None else f"--distance {distance_mm:g}",
             "mask": os.fspath(mask) if mask is not None else "the mask made from the pair"}
    return finish_pair(source_image, target_image, depth_map, mask_map, names), made


class PhotoInputs:
    """What :func:`photo_inputs` read: the pairs, the fit's ``fix`` and the record for params.json.

    Attributes
    ----------
    pairs : list of ImagePair
    fix : dict
        The user's ``fix`` with :data:`HELD_WITH_CONSTANT_DEPTH` added where the depth
        is constant and the user gave no value.
    record : dict or None
        ``params.json``'s ``inputs``: per pair how its ``depth`` and ``mask`` were
        obtained, and ``held``: each held parameter with its value and why. None when
        every pair came with a depth map and a mask (nothing to record).
    made_masks : dict
        ``{file name: (H, W) mask}`` of the masks made from the pairs, to write beside
        the result (``mask_used.png``; ``mask_used_0.png``, ... for several pairs).
    notices : list of str
        The masks' notices (:func:`~invsss.io.skin_mask.mask_checks`: a mask made with
        no face found, or covering most of the frame, touching most of its border,
        mostly failing the skin test), for ``params.json``'s ``warnings``.
    mask_notes : list of (str or None)
        Per pair, one short line on what its mask's checks found, for the report figure
        (:func:`~invsss.io.skin_mask.mask_note`); None where they passed or did not run.
    """

    def __init__(self, pairs, fix, record, made_masks, notices=(), mask_notes=None):
        self.pairs, self.fix, self.record, self.made_masks = pairs, fix, record, made_masks
        self.notices = list(notices)
        self.mask_notes = list(mask_notes) if mask_notes is not None else [None] * len(pairs)


def photo_inputs(sources, targets, depths, distances, masks, *, fix=None, depth_scale: float = 1.0,
                 linear_codes: bool = False) -> PhotoInputs:
    """The pairs of ``invsss fit``, any of them with ``--distance`` instead of ``--depth`` or
    without ``--mask``.

    ``depths`` and ``distances`` hold one entry per pair between them: either one
    ``--depth`` per pair or one ``--distance`` per pair (or a single ``--distance`` for
    all). ``masks`` is empty (make each pair's mask) or one per pair. A mask made, or a
    mask given with a distance (a photograph's pair), is checked
    (:func:`~invsss.io.skin_mask.make_skin_mask`, :func:`~invsss.io.skin_mask.check_skin_mask`):
    ``inputs.pairs[k].mask`` records the rule and the checks, and the notices are warned
    and kept in :attr:`PhotoInputs.notices`.

    Raises
    ------
    InvalidInputError
        Counts that do not match the pairs, ``--depth`` and ``--distance`` together, a
        distance that is not a finite number > 0, and everything the readers refuse.
    """
    count = len(sources)
    fix = dict(fix or {})
    check_photo_arguments(count, depths, distances, masks)
    distances = [float(d) for d in distances] * (count if len(distances) == 1 else 1)
    pairs, made, pair_records, notices, notes = [], {}, [], [], []
    for k in range(count):
        name = _mask_file(k, count)
        pair, made_mask = load_photo_pair(
            sources[k], targets[k], depth=depths[k] if depths else None,
            distance_mm=distances[k] if distances else None, mask=masks[k] if masks else None,
            depth_scale=depth_scale, linear_codes=linear_codes, mask_name=name,
        )
        pairs.append(pair)
        if made_mask is not None:
            made[name] = np.asarray(pair.mask, np.float32)
            mask_record = {"kind": "made from the pair", "file": name,
                           "function": "invsss.io.skin_mask.make_skin_mask", **made_mask.record()}
        else:
            mask_record = {"kind": "file", "file": os.fspath(masks[k])}
            if distances:  # a photograph's pair with its own mask: is it skin?
                mask_record.update(check_skin_mask(np.asarray(pair.mask), np.asarray(pair.source),
                                                   np.asarray(pair.target), os.fspath(masks[k])))
        notices += mask_record.get("notices", [])
        notes.append(mask_note(mask_record))
        pair_records.append({
            "depth": ({"kind": "distance", "distance_mm": distances[k]} if distances
                      else {"kind": "file", "file": os.fspath(depths[k]), "scale": depth_scale}),
            "mask": mask_record,
        })
    if not distances and not made:
        return PhotoInputs(pairs, fix, None, made)
    held = {}
    if distances:
        for name, default in HELD_WITH_CONSTANT_DEPTH.items():
            value = float(fix.get(name, default))
            fix[name] = value
            held[name] = {"value": value, "why": _HELD_REASON.format(name=name, value=value)}
    return PhotoInputs(pairs, fix, {"pairs": pair_records, "held": held}, made, notices, notes)


def _mask_file(k: int, count: int) -> str:
    return MASK_FILE if count == 1 else MASK_FILE.replace(".png", f"_{k}.png")


def check_photo_arguments(count: int, depths, distances, masks) -> list[str]:
    """Check ``--depth``/``--distance``/``--mask`` against ``count`` pairs before anything is read.

    Returns the names of the mask files the fit will write (none when every pair has
    ``--mask``).

    Examples
    --------
    >>> check_photo_arguments(1, [], [600.0], [])
    ['mask_used.png']
    >>> check_photo_arguments(1, ["d.exr"], [600.0], [])
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: --depth, --distance: give one or the other (a depth map, or one distance), not both
    """  # noqa: E501
    if depths and distances:
        raise InvalidInputError("--depth, --distance: give one or the other (a depth map, or one distance), not both")
    if not depths and not distances:
        raise InvalidInputError("--depth, --distance: give a depth map (--depth FILE, mm) or the face's "
                                "distance from the camera (--distance MM)")
    if depths and len(depths) != count:
        raise InvalidInputError(f"--depth: expected one per pair ({count}), got {len(depths)}")
    if distances and len(distances) not in (1, count):
        raise InvalidInputError(
            f"--distance: expected one for all pairs or one per pair ({count}), got {len(distances)}"
        )
    if masks and len(masks) != count:
        raise InvalidInputError(f"--mask: expected one per pair ({count}), got {len(masks)}")
    for value in distances:
        check_distance(value, "--distance", notice=False)  # noted once, where the depth is made
    return [] if masks else [_mask_file(k, count) for k in range(count)]
