"""One training example of the estimator: ``(source, depth, mask) -> target``.

:func:`invsss.load_pair` returns it from files, :func:`invsss.fit_pairs` accepts it
(or plain tuples), and the estimator works on its float64 form
(:meth:`ImagePair.as_float64`). One type for all three, so an attribute added for
the estimator is there for a pair read from disk too.
"""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError, depth_is_valid, is_concrete

__all__ = ["ImagePair", "fill_background_depth"]


def _as_hwc64(x) -> Array:
    x = np.asarray(x, dtype=np.float64)
    # device_put, not jnp.asarray: that compiles a small copy for every new shape.
    return jax.device_put(x[..., None] if x.ndim == 2 else x)


class ImagePair(eqx.Module):
    """One example for the fit: ``(source, depth, mask) -> target``.

    The constructor stores the arrays as given; :func:`invsss.load_pair` and
    :func:`invsss.estimator.inputs.prepare_pair` are the places that check them.

    Attributes
    ----------
    source : array, shape (H, W, C), C in {1, 3}
        Linear image without scattering.
    target : array, shape (H, W, C') or (H, W)
        Linear photograph to match; C' = C, or 1 (grey) for an RGB source.
    depth : array, shape (H, W), > 0
    mask : array, shape (H, W), in [0, 1], not all zero
    target_ndim : int, static
        2 when the target was given as (H, W): a fit returns its prediction so.
    fit_weight : array, shape (H, W), in [0, 1], or None
        Where the fit's residual counts, on top of the mask (None: everywhere the
        mask is on). The model still treats every masked pixel as skin; this only
        leaves pixels out of the comparison (an aligned fit drops the mask's rim,
        whose resampled values are least reliable).
    normal, light : array, shape (H, W, 3), or None
        Camera-space unit normals and unit vectors towards the light, the buffers
        of the light-aware terms (:mod:`invsss.forward.light_terms`; None without them).
    key : array, shape (H, W, C), or None
        The source lit by the key light alone (the ``law`` term; None without it).
    fill_light : array, shape (H, W, 3), or None
        Camera-space unit vectors towards the other lights (the ``fill`` term).
    thickness : array, shape (H, W), or None
        The distance in mm the key light travels inside the skin (the
        ``transmission`` term).
    key_irradiance : array, shape (H, W, C), or None
        The albedo times the key light's unshadowed irradiance (the ``transmission`` term).
    inputs_noted : bool, static
        True when :func:`invsss.load_pair` has already given the notices about the
        inputs as read, naming the files (background in the mask,
        :func:`invsss.validation.check_mask_background`; depth in coarse steps,
        :func:`invsss.validation.check_depth_steps`), so that a fit does not give them
        again, and not wrongly on the depth whose background it has filled.

    Examples
    --------
    >>> import numpy as np, invsss
    >>> pair = invsss.ImagePair(np.ones((4, 6, 3)), np.ones((4, 6)), np.full((4, 6), 500.0),
    ...                         np.ones((4, 6)))
    >>> data = pair.as_float64()  # under jax.enable_x64 to keep float64
    >>> data.target.shape, data.target_ndim, data.channels
    ((4, 6, 1), 2, (3, 1))
    """

    source: Float[Array, "H W C"]
    target: Float[Array, "H W Ct"]
    depth: Float[Array, "H W"]
    mask: Float[Array, "H W"]
    target_ndim: int = eqx.field(static=True, default=3)
    fit_weight: Float[Array, "H W"] | None = None
    normal: Float[Array, "H W 3"] | None = None
    light: Float[Array, "H W 3"] | None = None
    key: Float[Array, "H W C"] | None = None
    fill_light: Float[Array, "H W 3"] | None = None
    inputs_noted: bool = eqx.field(static=True, default=False)
    thickness: Float[Array, "H W"] | None = None
    key_irradiance: Float[Array, "H W C"] | None = None

    @property
    def light_buffers(self):
        """The pair's buffers of the light-aware terms as an :class:`invsss.LightBuffers`."""
        from .light_terms import LightBuffers

        return LightBuffers(self.normal, self.light, self.key, self.fill_light, self.thickness, self.key_irradiance)

    @property
    def residual_weight(self) -> Float[Array, "H W"]:
        """``mask * fit_weight``: how much each pixel's residual counts."""
        return self.mask if self.fit_weight is None else self.mask * self.fit_weight

    @property
    def channels(self) -> tuple[int, int]:
        """(source channels, target channels); a (H, W) array counts as 1 channel."""
        count = lambda x: int(np.shape(x)[-1]) if np.ndim(x) == 3 else 1  # noqa: E731
        return count(self.source), count(self.target)

    def as_float64(self) -> ImagePair:
        """The same pair as JAX float64 arrays with a channel axis on source and target.

        Call it under ``jax.enable_x64``; outside it JAX keeps float32.
        """
        target_ndim = 2 if np.ndim(self.target) == 2 else self.target_ndim
        return ImagePair(
            _as_hwc64(self.source),
            _as_hwc64(self.target),
            jax.device_put(np.asarray(self.depth, dtype=np.float64)),
            jax.device_put(np.asarray(self.mask, dtype=np.float64)),
            target_ndim,
            _float64_or_none(self.fit_weight),
            _float64_or_none(self.normal),
            _float64_or_none(self.light),
            None if self.key is None else _as_hwc64(self.key),
            _float64_or_none(self.fill_light),
            self.inputs_noted,
            _float64_or_none(self.thickness),
            None if self.key_irradiance is None else _as_hwc64(self.key_irradiance),
        )


def _float64_or_none(x):
    return None if x is None else jax.device_put(np.asarray(x, dtype=np.float64))


def fill_background_depth(depth):
    """``depth`` with every unusable pixel (0, negative, NaN, inf) set to the nearest usable one.

    Renderers write 0 or +inf depth where nothing was seen. The model must never
    see those values: the depth slopes at a masked pixel read its neighbours, and
    the pass ``image + mask * (blurred - image)`` turns a NaN blur into NaN even
    where the mask is 0. Copying the nearest valid depth continues the surface
    flat into the background, so a masked pixel beside it gets a small one-sided
    slope rather than a jump to a far plane. Call it after
    :func:`invsss.validation.check_depth` has made sure the masked pixels are
    valid; :func:`invsss.render`, :func:`invsss.load_pair` and the estimator do.

    Parameters
    ----------
    depth : array, shape (H, W)
        A concrete array; a tracer (inside ``jit``) is returned unchanged.

    Returns
    -------
    array, shape (H, W)
        ``depth`` itself when every pixel is valid, else a NumPy copy, same dtype.

    Raises
    ------
    InvalidInputError
        No pixel at all has finite depth > 0.

    Examples
    --------
    >>> import numpy as np
    >>> depth = np.array([[0.0, 500.0, 510.0, np.inf]])
    >>> fill_background_depth(depth)
    array([[500., 500., 510., 510.]])
    """
    if not is_concrete(depth):
        return depth
    valid = depth_is_valid(depth)
    if valid.all():
        return depth
    if not valid.any():
        raise InvalidInputError("depth: no pixel has finite depth > 0")
    from scipy.ndimage import distance_transform_edt  # only needed for renderer-style depth

    d = np.asarray(depth)
    rows, cols = distance_transform_edt(~valid, return_distances=False, return_indices=True)
    return d[rows, cols]
