"""Checked, float64 copies of the image pairs an estimator fits.

Everything that can be wrong with the user's arrays is caught here, before any
tracing, with one-line :class:`~invsss.validation.InvalidInputError` messages that
name the input (``pairs[1].target`` for the second pair of :func:`fit_pairs`).
The checks themselves are :func:`invsss.validation.check_pair`, shared with
:func:`invsss.load_pair`.
"""

from __future__ import annotations

import numpy as np

from ..forward.light_terms import LightBuffers
from ..forward.pair import ImagePair, fill_background_depth
from ..validation import InvalidInputError, check_pair

__all__ = ["prepare_pair", "prepare_pairs"]

def _check_fit_weight(fit_weight, shape, mask, name: str):
    weight = np.asarray(fit_weight, np.float64)
    if weight.shape != tuple(shape):
        raise InvalidInputError(f"{name}: expected shape {tuple(shape)} (the mask's), got {weight.shape}", field=name)
    if not np.all(np.isfinite(weight)) or weight.min() < 0 or weight.max() > 1:
        raise InvalidInputError(f"{name}: expected finite values in [0, 1]", field=name)
    if not np.any(weight * np.asarray(mask) > 0):
        raise InvalidInputError(f"{name}: leaves no masked pixel in the fit", field=name)
    return weight


def prepare_pair(source, target, depth, mask=None, *, fit_weight=None, normal=None, light=None, key=None,
                 fill_light=None, thickness=None, key_irradiance=None, name: str = "",
                 inputs_noted: bool = False) -> ImagePair:
    """Validate one pair and convert it to float64 (call under ``jax.enable_x64``).

    ``mask=None`` fits every pixel. ``name`` prefixes the input names in errors.
    ``inputs_noted`` skips the notices about the inputs (a pair from
    :func:`invsss.load_pair` has had them, on the depth as read).
    ``normal``, ``light``, ``key``, ``fill_light``, ``thickness`` and ``key_irradiance`` are the
    optional buffers of the light-aware terms (:class:`invsss.LightBuffers`), checked (and the
    vectors normalised) here.

    Examples
    --------
    >>> import jax, numpy as np
    >>> with jax.enable_x64(True):
    ...     data = prepare_pair(np.ones((4, 6, 3)), np.ones((4, 6)), np.full((4, 6), 500.0))
    >>> data.channels, data.target_ndim, str(data.depth.dtype)
    ((3, 1), 2, 'float64')
    """
    names = {key: f"{name}{key}" for key in ("source", "target", "depth", "mask")}
    check_pair(source, target, depth, mask, names, notices=not inputs_noted)
    if mask is None:
        mask = np.ones(np.shape(source)[:2])
    # Renderer-style background depth (0, inf) never reaches the model.
    depth = fill_background_depth(depth)
    if fit_weight is not None:
        fit_weight = _check_fit_weight(fit_weight, np.shape(mask), mask, f"{name}fit_weight")
    channels = np.shape(source)[2] if np.ndim(source) == 3 else 1
    buffers = LightBuffers(normal, light, key, fill_light, thickness, key_irradiance).checked(
        np.shape(mask), mask, prefix=name, channels=channels)
    return ImagePair(source, target, depth, mask, fit_weight=fit_weight, normal=buffers.normal,
                     light=buffers.light, key=buffers.key, fill_light=buffers.fill_light,
                     thickness=buffers.thickness, key_irradiance=buffers.key_irradiance,
                     inputs_noted=True).as_float64()


def _unpack(pair, index: int):
    if isinstance(pair, ImagePair):
        return (pair.source, pair.target, pair.depth, pair.mask, pair.fit_weight, pair.normal, pair.light,
                pair.key, pair.fill_light, pair.thickness, pair.key_irradiance, pair.inputs_noted)
    if isinstance(pair, (tuple, list)) and len(pair) in (3, 4):
        return (*pair, *(None,) * (11 - len(pair)), False)
    raise InvalidInputError(
        f"pairs[{index}]: expected a (source, target, depth, mask) tuple or an "
        f"invsss.ImagePair, got {type(pair).__name__}"
    )


def prepare_pairs(pairs) -> tuple[ImagePair, ...]:
    """Validate a sequence of pairs; all must have the same channel layout."""
    if isinstance(pairs, (str, bytes)) or not hasattr(pairs, "__len__") or len(pairs) == 0:
        raise InvalidInputError("pairs: expected a non-empty sequence of (source, target, depth, mask)")
    prepared = []
    for i, p in enumerate(pairs):
        (source, target, depth, mask, fit_weight, normal, light, key, fill_light, thickness, key_irradiance,
         checked) = _unpack(p, i)
        prepared.append(prepare_pair(source, target, depth, mask, fit_weight=fit_weight, normal=normal, light=light,
                                     key=key, fill_light=fill_light, thickness=thickness,
                                     key_irradiance=key_irradiance, name=f"pairs[{i}]." if len(pairs) > 1 else "",
                                     inputs_noted=checked))
    out = tuple(prepared)
    layouts = {p.channels for p in out}
    if len(layouts) > 1:
        raise InvalidInputError(
            "pairs: every pair must have the same (source, target) channel counts, got "
            + ", ".join(f"{a}->{b}" for a, b in sorted(layouts))
        )
    return out
