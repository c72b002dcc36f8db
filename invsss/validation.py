"""Input validation at the public boundary.

Every check here raises :class:`InvalidInputError` with a single line that names
the input and says what was expected. The forward model and the estimator call
these before anything is traced, so a user never sees a traceback from inside
JAX for a bad input. Checks on *values* (NaN, sign, empty mask) only run on
concrete arrays: under ``jax.jit`` the inputs are tracers and the caller is
responsible (the file readers in :mod:`invsss.io` always validate).
"""

from __future__ import annotations

import difflib
import json
import numbers
import warnings

import jax
import numpy as np

__all__ = [
    "InputNotice",
    "InvalidInputError",
    "check_image",
    "check_depth",
    "depth_is_valid",
    "check_mask",
    "check_same_size",
    "check_same_frame",
    "check_pair",
    "number_array",
    "positive_number",
    "check_target_channels",
    "check_mask_background",
    "check_depth_steps",
    "is_concrete",
    "one_line",
    "error_line",
    "did_you_mean",
]


class InvalidInputError(ValueError):
    """An input (array, file or config) is not what invsss expects.

    Parameters
    ----------
    message : str
        One line that names the input and says what was expected.
    field : str, optional
        The input the message is about, as the library names it (an option such
        as ``"saturation"``, a pair's role such as ``"pairs[1].mask"``, a buffer
        such as ``"light_buffers.key"``), where the message starts with it.
        Callers that show the input under another name (the command line shows
        a flag or a file's path) use :meth:`named`, never the message's text.
    path : str, optional
        The file the error is about, where there is one (an output that cannot
        be written, a pair's file the command line read for a role).

    Examples
    --------
    >>> err = InvalidInputError("saturation: expected a number > 0, got -1", field="saturation")
    >>> err.field
    'saturation'
    >>> str(err.named("--saturation"))
    '--saturation: expected a number > 0, got -1'
    >>> str(InvalidInputError("mask.png: mask is empty").named("--mask"))   # no field: unchanged
    'mask.png: mask is empty'
    """

    def __init__(self, message, *, field: str | None = None, path: str | None = None):
        super().__init__(message)
        self.field = field
        self.path = None if path is None else str(path)

    def named(self, label: str, path: str | None = None) -> InvalidInputError:
        """The same error with its field shown as ``label``; itself when it has no field.

        The result keeps ``field``, the library's name, and takes ``path`` (the
        file behind the label) when one is given.

        Examples
        --------
        >>> err = InvalidInputError("no skin in the mask", field="pairs[1].mask")
        >>> shown = err.named("cheek.png (pairs[1].mask)", "cheek.png")
        >>> str(shown), shown.field, shown.path
        ('cheek.png (pairs[1].mask): no skin in the mask', 'pairs[1].mask', 'cheek.png')
        """
        if self.field is None:
            return self
        text = str(self)
        # Messages start with their field by convention; one that does not is
        # still shown under the label rather than left under the library's name.
        rest = text[len(self.field):] if text.startswith(self.field) else f": {text}"
        named = InvalidInputError(label + rest, path=self.path if path is None else path)
        named.field = self.field
        return named


class InputNotice(UserWarning):
    """A note about how an input was interpreted (decoded as sRGB, alpha dropped, ...).

    Not an error: the input is used, but the user may have meant something else.
    Filter it with ``warnings.simplefilter("ignore", invsss.InputNotice)``.
    """


def one_line(text) -> str:
    r"""``text`` (or ``str(text)``) with every run of whitespace, newlines included, as one space.

    Messages from libraries (OpenImageIO, ``json``, the OS) may span lines; an
    invsss error is one line, so they are folded into it with this.

    Examples
    --------
    >>> one_line("cannot open\n  file.png:  no such file ")
    'cannot open file.png: no such file'
    """
    return " ".join(str(text).split())


def did_you_mean(key, known) -> str:
    """`` (did you mean 'x'?)`` for the known name closest to a misspelt ``key``, or ``""``.

    Examples
    --------
    >>> did_you_mean("shfit", ["shift", "grazing"])
    " (did you mean 'shift'?)"
    >>> did_you_mean("zzz", ["shift"])
    ''
    """
    close = difflib.get_close_matches(str(key), list(known), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def error_line(err: BaseException) -> str:
    r"""One line saying what went wrong in ``err``, led by its type unless it is an
    :class:`InvalidInputError` (whose message already names the input).

    Examples
    --------
    >>> error_line(InvalidInputError("mask.png: mask is empty"))
    'mask.png: mask is empty'
    >>> error_line(ZeroDivisionError("division\nby zero"))
    'ZeroDivisionError: division by zero'
    >>> error_line(KeyError())
    'KeyError'
    """
    text = one_line(err)
    if isinstance(err, InvalidInputError):
        return text or type(err).__name__
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def _shown(value) -> str:
    """A value as the user wrote it: JSON spelling where there is one (``true``, ``"600"``)."""
    try:
        return json.dumps(value)
    except (TypeError, ValueError):
        return repr(value)


def _first_non_number(value, key: str):
    """``(where, value)`` of the first entry of a nested list that is not a number, else None."""
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            found = _first_non_number(item, f"{key}[{i}]")
            if found:
                return found
        return None
    # bool is an int subclass, but ``true`` for a number is a mistake, never 1.
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return key, value
    return None


def positive_number(value, name: str) -> float:
    """``value`` as a finite float > 0, else a one-line error naming ``name``.

    Examples
    --------
    >>> positive_number("0.5", "mm_per_pixel")
    0.5
    >>> positive_number(0, "mm_per_pixel")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: mm_per_pixel: expected a finite number > 0, got 0
    >>> positive_number("wide", "band_width_mm")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: band_width_mm: expected a number, got 'wide'
    """
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name}: expected a number, got {value!r}", field=name) from None
    if not np.isfinite(x) or x <= 0:
        raise InvalidInputError(f"{name}: expected a finite number > 0, got {value!r}", field=name)
    return x


def number_array(value, key: str, source: str = "params") -> np.ndarray:
    """``value`` (a number, a nested list of numbers, or a numeric array) as float64.

    The single parser for numeric parameters: booleans and strings are refused
    (NumPy would turn ``True`` into 1.0 and ``"600"`` into 600.0), as are ragged
    lists, with one line naming ``source``, the entry and the value.

    Examples
    --------
    >>> number_array([0.5, 2], "variances")
    array([0.5, 2. ])
    >>> number_array([1.0, True], "weights", "params.json")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: params.json: weights[1]: expected a number, got true
    """
    if not is_concrete(value):
        return value  # a tracer: its dtype is the caller's business, values unknown
    if hasattr(value, "dtype") and hasattr(value, "shape"):  # NumPy, JAX, torch arrays
        array = np.asarray(value)
        if array.dtype.kind not in "iuf":
            raise InvalidInputError(f"{source}: {key}: expected numbers, got dtype {array.dtype}", field=source)
        return array.astype(np.float64)
    found = _first_non_number(value, key)
    if found:
        where, bad = found
        raise InvalidInputError(f"{source}: {where}: expected a number, got {_shown(bad)}", field=source)
    try:
        return np.asarray(value, dtype=np.float64)
    except ValueError:
        raise InvalidInputError(
            f"{source}: {key}: expected a rectangular list of numbers (every row the same length)",
            field=source,
        ) from None


def is_concrete(x) -> bool:
    """True when ``x`` holds values (not a tracer inside ``jit``/``grad``/``vmap``)."""
    return not isinstance(x, jax.core.Tracer)


def _shape(x):
    return tuple(np.shape(x))


def check_image(image, name: str = "image", *, allow_batch: bool = False) -> None:
    """An image is (H, W) or (H, W, C) with C in {1, 3}, H, W >= 2, finite floats."""
    shape = _shape(image)
    core = shape[-3:] if (allow_batch and len(shape) > 3) else shape
    if len(core) == 2:
        h, w = core
    elif len(core) == 3:
        h, w, c = core
        if c not in (1, 3):
            raise InvalidInputError(
                f"{name}: expected 1 or 3 channels in the last axis, got shape {shape}",
                field=name,
            )
    else:
        raise InvalidInputError(f"{name}: expected shape (H, W) or (H, W, C), got {shape}", field=name)
    if h < 2 or w < 2:
        raise InvalidInputError(f"{name}: expected at least 2x2 pixels, got shape {shape}", field=name)
    # Tracers have a dtype; only plain sequences need converting to find one.
    dtype = np.dtype(image.dtype if hasattr(image, "dtype") else np.asarray(image).dtype)
    if not np.issubdtype(dtype, np.floating):
        raise InvalidInputError(
            f"{name}: expected linear floating-point values, got dtype {dtype} "
            "(decode 8/16-bit images with invsss.read_image)",
            field=name,
        )
    if is_concrete(image) and not bool(np.all(np.isfinite(np.asarray(image)))):
        raise InvalidInputError(f"{name}: contains NaN or infinite values", field=name)


def depth_is_valid(depth) -> np.ndarray:
    """Boolean (H, W): where ``depth`` is usable, i.e. finite and > 0.

    Renderers and depth cameras write 0, a negative sentinel, NaN or +inf where
    nothing was seen; those pixels are the background, and are only allowed where
    the mask is 0.

    Examples
    --------
    >>> import numpy as np
    >>> depth_is_valid(np.array([[500.0, 0.0], [np.inf, -1.0]]))
    array([[ True, False],
           [False, False]])
    """
    d = np.asarray(depth)
    with np.errstate(invalid="ignore"):
        return np.isfinite(d) & (d > 0)


def check_depth(depth, shape_hw: tuple[int, int], name: str = "depth", mask=None) -> None:
    """Depth is (H, W), finite and > 0 wherever the mask is 1.

    With ``mask=None`` every pixel counts as masked. Off the mask (the background),
    depth may be 0, NaN or infinite as renderers write it: the model never uses
    it there once :func:`invsss.forward.pair.fill_background_depth` has replaced it, which
    every public entry point does. So may it on the mask's soft edge (0 < mask < 1):
    an anti-aliased mask reaches into pixels whose depth sample saw the background,
    and the fill gives them the nearest skin's depth. Pass a mask already checked with
    :func:`check_mask`.

    Examples
    --------
    >>> import numpy as np
    >>> depth = np.full((4, 4), 500.0); depth[:, 0] = np.inf
    >>> mask = np.ones((4, 4)); mask[:, 0] = 0.0
    >>> check_depth(depth, (4, 4), "depth.exr", mask)  # background only: fine
    >>> check_depth(depth, (4, 4), "depth.exr")
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: depth.exr: expected finite depth > 0 on every pixel (no mask given), 4 pixel(s) are not (NaN, infinite or <= 0)
    """  # noqa: E501
    shape = _shape(depth)
    if shape != tuple(shape_hw):
        raise InvalidInputError(
            f"{name}: expected shape {tuple(shape_hw)} to match the image, got {shape}",
            field=name,
        )
    if not (is_concrete(depth) and (mask is None or is_concrete(mask))):
        return
    invalid = ~depth_is_valid(depth)
    if mask is None:
        bad, where = int(np.count_nonzero(invalid)), "on every pixel (no mask given)"
    else:
        bad = int(np.count_nonzero(invalid & (np.asarray(mask) >= 1)))
        where = "wherever the mask is 1"
    if bad:
        what = "pixel(s) are" if mask is None else "masked pixel(s) are"
        raise InvalidInputError(
            f"{name}: expected finite depth > 0 {where}, {bad} {what} not "
            "(NaN, infinite or <= 0)",
            field=name,
        )


def check_mask(mask, shape_hw: tuple[int, int], name: str = "mask") -> None:
    """Mask is (H, W) in [0, 1] with at least one non-zero pixel."""
    shape = _shape(mask)
    if shape != tuple(shape_hw):
        raise InvalidInputError(
            f"{name}: expected shape {tuple(shape_hw)} to match the image, got {shape}",
            field=name,
        )
    if is_concrete(mask):
        m = np.asarray(mask)
        if not np.all(np.isfinite(m)):
            raise InvalidInputError(f"{name}: expected values in [0, 1], got NaN or infinite values", field=name)
        if m.min() < 0 or m.max() > 1:
            hint = " (a 0/255 mask? read mask files with invsss.read_mask)" if m.max() > 1 else ""
            raise InvalidInputError(f"{name}: expected values in [0, 1], got {m.min():g} to {m.max():g}{hint}",
                                    field=name)
        if not np.any(m > 0):
            raise InvalidInputError(f"{name}: is empty (no pixel > 0)", field=name)


def check_same_size(a_shape, b_shape, a_name: str, b_name: str) -> None:
    if tuple(a_shape[:2]) != tuple(b_shape[:2]):
        raise InvalidInputError(
            f"{b_name}: expected {a_shape[0]}x{a_shape[1]} pixels to match {a_name}, "
            f"got {b_shape[0]}x{b_shape[1]} (every image of a pair is on one pixel grid: crop or "
            "resample them to it; --align registers a shift or rotation, not another size)",
            field=b_name,
        )


def check_same_frame(named_arrays) -> None:
    """Every ``(name, array)`` in ``named_arrays`` has the pixel size (H, W) of the first.

    ``None`` arrays (an omitted mask) are skipped. The error names the odd one out
    and the reference, e.g. ``depth.exr: expected 12x16 pixels to match image.exr``.

    Examples
    --------
    >>> import numpy as np
    >>> check_same_frame([("image", np.zeros((4, 6, 3))), ("depth", np.zeros((4, 5)))])
    Traceback (most recent call last):
    ...
    invsss.validation.InvalidInputError: depth: expected 4x6 pixels to match image, got 4x5 (every image of a pair is on one pixel grid: crop or resample them to it; --align registers a shift or rotation, not another size)
    """  # noqa: E501
    (reference_name, reference), *others = named_arrays
    for name, array in others:
        if array is not None:
            check_same_size(np.shape(reference), np.shape(array), reference_name, name)


def check_target_channels(source_channels: int, target_channels: int, target_name: str) -> None:
    """A target has the source's channel count, or 1 (grey) for an RGB source."""
    if target_channels != source_channels and not (source_channels == 3 and target_channels == 1):
        hint = (" (a colour target needs a colour source; for a grey source, give the target as grey too)"
                if source_channels == 1 else " (or 1: a grey target of an RGB source)")
        raise InvalidInputError(
            f"{target_name}: expected {source_channels} channel(s) like the source{hint}, got {target_channels}",
            field=target_name,
        )


#: A mask with more of the frame than this is probably not just skin.
MASK_WHOLE_FRAME = 0.98
#: Pixels sharing the depth maximum, as a fraction of the frame, that make it a far plane.
FAR_PLANE_SHARE = 0.01


def check_mask_background(mask, depth, mask_name: str = "mask") -> None:
    """Warn (:class:`InputNotice`) when a skin mask very likely includes background.

    Two signs: the mask covers more than ``MASK_WHOLE_FRAME`` of the frame, or
    it is > 0 on the depth's far plane (the maximum depth, shared by more than
    ``FAR_PLANE_SHARE`` of the pixels but not by all, as a renderer's or depth
    camera's background is). Background pixels pull the fit towards "no scattering".
    Skipped for tracers.

    Examples
    --------
    >>> import numpy as np, warnings
    >>> depth = np.full((10, 10), 500.0); depth[:, 5:] = 1e4  # right half is far plane
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_mask_background(np.ones((10, 10)), depth, "mask.png")
    >>> [str(w.message).split(";")[0] for w in caught]
    ['mask.png: covers 100% of the frame']
    """
    if not (is_concrete(mask) and is_concrete(depth)):
        return
    m, d = np.asarray(mask) > 0, np.asarray(depth)
    valid = depth_is_valid(d)
    coverage = float(m.mean())
    if coverage > MASK_WHOLE_FRAME:
        warnings.warn(
            f"{mask_name}: covers {coverage:.0%} of the frame; it likely includes background "
            "(the mask should select skin only)",
            InputNotice,
            stacklevel=3,
        )
        return
    if not valid.all():
        # The background is marked explicitly (0 or inf, as renderers write it):
        # there is no far plane to guess, and masked pixels are checked valid.
        return
    far = d == d.max()
    on_far_plane = int(np.count_nonzero(m & far))
    # A depth map that is one flat plane has no background to tell apart.
    if FAR_PLANE_SHARE < far.mean() < 1.0 and on_far_plane:
        warnings.warn(
            f"{mask_name}: {on_far_plane} masked pixel(s) lie on the depth's far plane "
            f"({float(d.max()):g}); the mask likely includes background",
            InputNotice,
            stacklevel=3,
        )


#: Depth in steps where more than this share of neighbouring skin pixels have one
#: depth gets a notice (:func:`check_depth_steps`). Measured on ``fran_front``'s
#: neighbours: 0 as rendered, 7.6 % in tenths of a mm (a fit as good), 18 % in a half
#: float's 0.25 mm (correction 7 % low), 57 % in whole mm (54 % low).
DEPTH_EQUAL_SHARE = 0.15


def check_depth_steps(depth, mask=None, name: str = "depth") -> None:
    """Warn (:class:`InputNotice`) when the depth on the skin comes in steps coarser
    than its slopes between neighbouring pixels.

    The correction reads the depth's slope at each pixel; a depth map rounded to
    whole millimetres (a 16-bit PNG in mm, a depth camera) turns a face's slopes of
    a third of a millimetre per pixel into steps of 0 and 1, and biases the fit
    without lowering its PSNR much. Measured on ``fran_front`` (the truth 600 and
    800; unrounded 598 +- 4 and 814): rounded to whole mm, sss_level 758 +- 17 and
    correction 371 +- 15; to a half float's 0.25 mm, 593 +- 7 and 757 +- 9; to tenths
    of a mm, 601 and 808. The steps are the smallest difference between depths on
    the skin (where the mask is 1, or everywhere without one), if every depth there
    is a whole number of them (at least three levels); the notice fires when more
    than :data:`DEPTH_EQUAL_SHARE` of the neighbouring skin pixels then have one
    depth (a tilted plane in exact steps has none, and is left alone). Skipped for
    tracers.

    Examples
    --------
    >>> import numpy as np, warnings
    >>> y, x = np.mgrid[0:32, 0:32]
    >>> face = 500.0 + 0.01 * ((x - 16.0) ** 2 + (y - 16.0) ** 2)  # slopes up to 0.3 mm a pixel
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_depth_steps(np.round(face), None, "depth.png")
    ...     check_depth_steps(face, None, "depth.exr")
    >>> [str(w.message).split(" (")[0] for w in caught]
    ['depth.png: the depth on the skin comes in steps of 1']
    """
    if not (is_concrete(depth) and (mask is None or is_concrete(mask))):
        return
    d = np.asarray(depth, np.float64)
    skin = depth_is_valid(d) & (True if mask is None else np.asarray(mask) >= 1)
    slopes = np.concatenate([np.diff(d, axis=1)[skin[:, 1:] & skin[:, :-1]],
                             np.diff(d, axis=0)[skin[1:] & skin[:-1]]])
    equal = float(np.mean(slopes == 0)) if slopes.size else 0.0
    # The share first, in one pass: rendered depth has none, and skips the sort below.
    if equal <= DEPTH_EQUAL_SHARE:
        return
    values = np.unique(d[skin])
    if values.size < 3:  # one plane (a photograph's constant distance): no slopes to read
        return
    step = float(np.diff(values).min())
    levels = (values - values[0]) / step
    if np.allclose(levels, np.round(levels), rtol=0.0, atol=1e-3):
        warnings.warn(
            f"{name}: the depth on the skin comes in steps of {step:g} (whole mm in a 16-bit PNG? a half "
            f"float?), and {equal:.0%} of neighbouring skin pixels share one depth; the slopes the correction "
            "reads are then steps too, which biases correction and sss_level (fran_front in whole mm: "
            "sss_level +27 %, correction -54 %). Give depth in finer steps (tenths of a mm: --depth-scale 0.1) "
            "or as float32",
            InputNotice,
            stacklevel=3,
        )


def check_pair(source, target, depth, mask, names, *, notices: bool = True) -> None:
    """Check one ``(source, target, depth, mask)`` example; ``names`` names each input.

    The one place that checks an example's shapes, sizes and channel layout, for
    arrays and for files alike: ``names`` maps ``"source"``, ``"target"``,
    ``"depth"``, ``"mask"`` to what the messages call them (file paths, or
    ``pairs[1].target``). ``mask=None`` means every pixel and is not checked.
    ``notices=False`` skips the notices of :func:`check_mask_background` and
    :func:`check_depth_steps` (given once already).
    """
    check_image(source, names["source"])
    check_image(target, names["target"])
    arrays = {"source": source, "target": target, "depth": depth, "mask": mask}
    check_same_frame([(names[key], array) for key, array in arrays.items()])
    hw = tuple(np.shape(source)[:2])
    channels = lambda x: int(np.shape(x)[-1]) if np.ndim(x) == 3 else 1  # noqa: E731
    if mask is not None:
        check_mask(mask, hw, names["mask"])
    # Depth is checked where the mask needs it, so the mask comes first.
    check_depth(depth, hw, names["depth"], mask)
    check_target_channels(channels(source), channels(target), names["target"])
    if notices:
        check_depth_steps(depth, mask, names["depth"])
        if mask is not None:
            check_mask_background(mask, depth, names["mask"])
