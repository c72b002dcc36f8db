"""The per-pixel buffers of the light-aware terms (:mod:`invsss.forward.light_terms`),
which terms need which, and their checks at the boundary.

A renderer's buffers come in camera space (x right, y up, z towards the camera):
unit vectors (``normal``, ``light``, ``fill_light``), images in the source's units
(``key``, ``key_irradiance``) and a thickness in mm. :meth:`LightBuffers.checked`
refuses what cannot be right (a wrong shape, NaN on the mask, vectors that are not
unit length, a negative thickness) with one line naming the buffer.
"""

from __future__ import annotations

import equinox as eqx
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError

__all__ = ["LightBuffers", "NEEDED_BUFFERS", "BUFFER_MEANINGS", "UNIT_TOLERANCE"]

#: The buffers each term needs.
NEEDED_BUFFERS = {"shift": ("light",), "grazing": ("normal",), "incidence": ("normal", "light"),
                  "law": ("key", "normal", "light"), "fill": ("key", "normal", "fill_light"),
                  "transmission": ("thickness", "key_irradiance", "normal", "light")}
#: What each buffer holds, for the error that names a missing one.
BUFFER_MEANINGS = {
    "normal": "camera-space unit vectors, shape (H, W, 3)",
    "light": "camera-space unit vectors, shape (H, W, 3)",
    "fill_light": "camera-space unit vectors, shape (H, W, 3)",
    "key": "the source lit by the key light alone, shape (H, W, C)",
    "key_irradiance": "the albedo times the key light's unshadowed irradiance on a surface facing it, shape (H, W, C)",
    "thickness": "the distance in mm the key light travels inside the skin, shape (H, W)",
}

#: How far from unit length a buffer's vectors may be before it is refused
#: (8-bit normal maps are off by about 1 %; a wrongly decoded map by far more).
UNIT_TOLERANCE = 0.05


def _numbers(array, name: str) -> np.ndarray:
    """``array`` as float64, or one line naming the buffer when it is not numbers."""
    try:
        return np.asarray(array, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name}: expected an array of numbers, got {type(array).__name__}",
                                field=name) from None


def _check_unit_vectors(array, shape, mask, name: str):
    a = _numbers(array, name)
    if a.shape != (*shape, 3):
        raise InvalidInputError(f"{name}: expected shape {(*shape, 3)} (unit vectors per pixel), got {a.shape}",
                                field=name)
    on = np.asarray(mask) > 0
    values = a[on]
    if not np.all(np.isfinite(values)):
        raise InvalidInputError(f"{name}: NaN or infinite vectors on the mask", field=name)
    length = np.linalg.norm(values, axis=-1)
    worst = float(np.max(np.abs(length - 1.0))) if length.size else 0.0
    if worst > UNIT_TOLERANCE:
        raise InvalidInputError(
            f"{name}: expected unit vectors in camera space on the mask, but a length is off by "
            f"{worst:.2g} (an 8-bit map must be decoded to [-1, 1] first)",
            field=name,
        )
    # Off the mask a renderer writes zeros; give those a harmless unit vector.
    safe = np.where(np.linalg.norm(a, axis=-1, keepdims=True) > 0.5, a, np.array([0.0, 0.0, 1.0]))
    return safe / np.linalg.norm(safe, axis=-1, keepdims=True)


def _check_thickness(array, shape, mask, name: str):
    a = _numbers(array, name)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.shape != tuple(shape):
        raise InvalidInputError(f"{name}: expected shape {tuple(shape)} (mm per pixel), got {np.shape(array)}",
                                field=name)
    on = np.asarray(mask) > 0
    values = a[on]
    if not np.all(np.isfinite(values)):
        raise InvalidInputError(f"{name}: NaN or infinite thickness on the mask (expected mm >= 0)", field=name)
    if values.size and float(values.min()) < 0.0:
        raise InvalidInputError(f"{name}: expected a thickness >= 0 mm on the mask, got {float(values.min()):g}",
                                field=name)
    # Off the mask the term is multiplied by 0, but a NaN there would still poison it.
    return np.where(np.isfinite(a) & (a >= 0.0), a, 0.0)


def _check_key(array, shape, channels, name: str, mask=None, meaning="the key light's part of the source"):
    a = _numbers(array, name)
    if a.ndim == 2:
        a = a[..., None]
    wanted = (*shape, channels) if channels else None
    if a.ndim != 3 or a.shape[:2] != tuple(shape) or (wanted and a.shape != wanted):
        expected = wanted or (*shape, "C")
        raise InvalidInputError(
            f"{name}: expected shape {expected} ({meaning}), got {np.shape(array)}",
            field=name,
        )
    on = np.ones(a.shape[:2], bool) if mask is None else np.asarray(mask) > 0
    if not np.all(np.isfinite(a[on])):
        raise InvalidInputError(f"{name}: NaN or infinite values on the mask", field=name)
    # Off the mask the term does nothing (it is multiplied by the mask), but a
    # NaN there would still poison the product: a renderer's cleared buffer.
    return np.where(np.isfinite(a), a, 0.0)


class LightBuffers(eqx.Module):
    """Per-pixel buffers of the light-aware terms, camera space (x right, y up, z to the camera).

    Parameters
    ----------
    normal : array, shape (H, W, 3), optional
        Unit surface normals (the ``grazing``, ``incidence`` and ``law`` terms).
    light : array, shape (H, W, 3), optional
        Unit vectors from the surface point towards the key light (the
        ``shift``, ``incidence`` and ``law`` terms); for a point light
        ``normalize(light_position - position)``.
    key : array, shape (H, W, C) or (H, W), optional
        The key light's part of the source: the source lit by that light alone,
        in the source's units (the ``law`` and ``fill`` terms). Linear radiance; a
        noisy render may dip slightly below 0.
    fill_light : array, shape (H, W, 3), optional
        Unit vectors from the surface point towards the other lights (the
        ``fill`` term): one direction standing for every light but the key, such
        as the strongest of them; ``invsss scene`` writes the second light's.
    thickness : array, shape (H, W) or (H, W, 1), optional
        The distance in mm the key light travels inside the skin before it
        reaches the seen point, >= 0 (the ``transmission`` term): what a shadow
        map gives, or a baked thickness map in mm; 0 where the point faces the
        light. ``invsss scene`` writes it as ``thickness.exr``.
    key_irradiance : array, shape (H, W, C) or (H, W), optional
        The albedo times the key light's irradiance on a surface facing it, with
        no shadow, in the source's units (the ``transmission`` term): where the key
        light reaches a point, ``key = key_irradiance * max(n . l, 0)``.

    Examples
    --------
    >>> import numpy as np
    >>> from invsss.forward.light_terms import LightBuffers
    >>> up = np.zeros((2, 3, 3)); up[..., 1] = 1.0
    >>> LightBuffers(light=up).light.shape
    (2, 3, 3)
    """

    normal: Float[Array, "H W 3"] | None = None
    light: Float[Array, "H W 3"] | None = None
    key: Float[Array, "H W C"] | None = None
    fill_light: Float[Array, "H W 3"] | None = None
    thickness: Float[Array, "H W"] | None = None
    key_irradiance: Float[Array, "H W C"] | None = None

    def checked(self, shape, mask, prefix: str = "light_buffers.", channels: int | None = None) -> LightBuffers:
        """Validated, normalised float64 NumPy copies for an image of ``shape`` (H, W).

        ``channels`` is the source's channel count, which the key buffer must
        have (any count when None); a (H, W) key gets a channel axis. Errors
        name the buffer as ``prefix + "normal"`` (or ``"light"``, ``"key"``, ``"fill_light"``).
        """
        return LightBuffers(
            None if self.normal is None else _check_unit_vectors(self.normal, shape, mask, f"{prefix}normal"),
            None if self.light is None else _check_unit_vectors(self.light, shape, mask, f"{prefix}light"),
            None if self.key is None else _check_key(self.key, shape, channels, f"{prefix}key", mask),
            None if self.fill_light is None else _check_unit_vectors(self.fill_light, shape, mask,
                                                                     f"{prefix}fill_light"),
            None if self.thickness is None else _check_thickness(self.thickness, shape, mask, f"{prefix}thickness"),
            None if self.key_irradiance is None else _check_key(self.key_irradiance, shape, channels,
                                                                f"{prefix}key_irradiance", mask,
                                                                meaning=BUFFER_MEANINGS["key_irradiance"]),
        )

    def require(self, terms, prefix: str = "light_buffers.") -> None:
        """Raise unless every buffer the named ``terms`` need is present."""
        for term in terms:
            for buffer in NEEDED_BUFFERS[term]:
                if getattr(self, buffer) is None:
                    raise InvalidInputError(
                        f"{prefix}{buffer}: the {term!r} term needs this buffer ({BUFFER_MEANINGS[buffer]})",
                        field=f"{prefix}{buffer}")
