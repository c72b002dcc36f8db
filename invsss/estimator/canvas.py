"""Pairs padded onto one canvas, so that pairs of different sizes share one compilation.

Every compiled function of a fit is specialised to the image sizes, so a sweep over
photographs of 250 x 238, 252 x 240, ... pixels compiles its solver step once per
size. Padded to one canvas (``FitOptions(canvas=(H, W))``), they compile once.

The padding leaves the fit as it is at the pair's own size: every pixel of the
pair gets the same prediction, and the rest add nothing. That holds because

- the added rows and columns (below and to the right) are outside the mask, so
  their residual has no weight and the passes leave them as they are;
- the source and the depth are continued with their last row and column. A pass
  returns every pixel where the mask is 0 unchanged, so when the mask is 0 on the
  pair's last row and column, that row and column stay equal to the source
  through every pass, and so does the padding beside them: a tap reading past the
  pair's edge then reads what clamp-to-edge addressing reads at the pair's own
  size (docs/model.md, section 3), up to the rounding of one interpolation;
- a masked pixel's depth slope reads its direct neighbours only, which are the
  pair's own.

Where the mask reaches the last row or column, the passes change that row or
column, the padding does not follow, and the blur near that edge would change:
such a pair is fitted at its own size, with a warning. So is every pair of a fit
with a term that depends on the frame: the vignetting (a field over the whole
frame), the light terms (which read the normal and light buffers and move the
image along the light) and the registration (which resamples onto the
photograph's grid).
"""

from __future__ import annotations

import jax
import numpy as np

from ..forward.pair import ImagePair
from ..validation import InvalidInputError

__all__ = ["frame_terms", "unused_note", "pad_pair", "crop", "on_canvas"]


def frame_terms(options) -> list[str]:
    """The options of a fit that keep it off a canvas (empty when it may use one)."""
    out = []
    if options.vignetting:
        out.append("vignetting")
    if options.pigment:
        out.append("pigment")
    if options.light_terms:
        out.append("light_terms")
    if options.align != "none":
        out.append("align")
    return out


def unused_note(blockers) -> str:
    """The warning of a fit that kept its pairs off the canvas because of ``blockers``."""
    which = "it depends" if len(blockers) == 1 else "they depend"
    return (f"canvas: not used with {', '.join(blockers)} ({which} on the frame); "
            "every pair was fitted at its own size")


def _pad(x, canvas, value=None):
    x = np.asarray(x)
    widths = [(0, canvas[0] - x.shape[0]), (0, canvas[1] - x.shape[1])] + [(0, 0)] * (x.ndim - 2)
    if value is None:
        return np.pad(x, widths, mode="edge")
    return np.pad(x, widths, mode="constant", constant_values=value)


def pad_pair(pair: ImagePair, canvas: tuple[int, int]) -> ImagePair:
    """A checked pair on a ``canvas`` (height, width) at least its size: the mask
    and fit weight padded with 0, every other buffer with its last row and column.

    Examples
    --------
    >>> import jax, numpy as np
    >>> from invsss.estimator.inputs import prepare_pair
    >>> with jax.enable_x64(True):
    ...     pair = prepare_pair(np.ones((3, 4)), np.ones((3, 4)), np.full((3, 4), 500.0))
    ...     padded = pad_pair(pair, (5, 4))
    >>> padded.source.shape, np.asarray(padded.mask)[:, 0].tolist()
    ((5, 4, 1), [1.0, 1.0, 1.0, 0.0, 0.0])
    """

    def put(x, value=None):
        return None if x is None else jax.device_put(_pad(x, canvas, value))

    return ImagePair(
        put(pair.source), put(pair.target), put(pair.depth), put(pair.mask, 0.0), target_ndim=pair.target_ndim,
        fit_weight=put(pair.fit_weight, 0.0), normal=put(pair.normal), light=put(pair.light), key=put(pair.key),
        fill_light=put(pair.fill_light), inputs_noted=pair.inputs_noted, thickness=put(pair.thickness),
        key_irradiance=put(pair.key_irradiance),
    )


def crop(image, shape) -> np.ndarray:
    """The top-left ``shape`` (height, width) of an image on a canvas."""
    return np.asarray(image)[: shape[0], : shape[1]]


def on_canvas(pairs, options) -> tuple[tuple, list[str]]:
    """The pairs padded to ``options.canvas`` where that leaves the fit unchanged,
    and a warning for each pair (or option) that keeps them at their own size.

    Raises
    ------
    InvalidInputError
        A pair larger than the canvas.
    """
    canvas = options.canvas
    if canvas is None:
        return tuple(pairs), []

    def name(i):
        return f"pairs[{i}]" if len(pairs) > 1 else "the pair"

    for i, pair in enumerate(pairs):
        h, w = np.shape(pair.mask)
        if h > canvas[0] or w > canvas[1]:
            raise InvalidInputError(
                f"canvas: {name(i)} is {h} x {w} pixels, larger than the canvas of {canvas[0]} x {canvas[1]}",
                field="canvas",
            )
    blockers = frame_terms(options)
    if blockers:
        return tuple(pairs), [unused_note(blockers)]
    out, notes = [], []
    for i, pair in enumerate(pairs):
        mask = np.asarray(pair.mask)
        h, w = mask.shape
        # Only an edge that gets padding matters.
        touches = (h < canvas[0] and np.any(mask[-1] != 0)) or (w < canvas[1] and np.any(mask[:, -1] != 0))
        if touches:
            notes.append(
                f"canvas: {name(i)}'s mask reaches its last row or column, where padding would change the "
                f"blur; it was fitted at its own size ({h} x {w})"
            )
            out.append(pair)
        else:
            out.append(pad_pair(pair, canvas) if (h, w) != tuple(canvas) else pair)
    return tuple(out), notes
