"""Registration of a target photograph onto its source: :func:`estimate_warp`, :func:`warp_image`.

A real pair is never pixel-aligned: the photograph is off by a few pixels and a
fraction of a degree from the render of the face scan. The screen-space model
cannot explain a shift (a one-pixel shift reads as a wrong blur), so the target is
resampled onto the source's pixel grid before it is compared with the model.

A warp maps a source pixel ``x = (row, col)`` to the target position
``A (x - c) + c + t`` where ``c`` is the centre of the skin mask:

==============  ==========================================================
``translation`` ``t`` (2 numbers: rows, columns)
``similarity``  ``t``, a rotation angle (radians) and a log scale: ``A = s R``
``affine``      ``t`` and ``A - I`` (4 numbers)
==============  ==========================================================

The warp is found by least squares between the target resampled at the warped
source grid and a reference image on the source grid (the photometrically matched
source at first, then the model's prediction with a first fit's parameters, which
carries the blur; see :func:`invsss.fit_pair`'s ``align``), with a free gain and
offset per channel, coarse to fine, started from a phase-correlation estimate of
the shift. Estimation resamples bilinearly (differentiable in JAX).

The fit itself never resamples the target: :func:`align_source` moves the source,
depth and mask onto the target's grid instead. Interpolation is a low-pass
filter, and a photograph's noise is white: resampling the target at a half-pixel
offset averages neighbouring noise, which the fit reads as extra blur. Measured on
``data_synthetic/fran_front`` (noise 1 % of the mean): a round trip of two
half-pixel cubic-spline shifts of the target, which moves nothing, raised the fitted
sss_level from 598 to 735 (+23 %; 757 with quintic splines), where an all-pass
Fourier round trip gave 602. The same cubic round trip applied to the noise-free
source moved sss_level by +0.5 % and correction by -3 %.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from scipy import ndimage

from ..forward.pair import fill_background_depth
from ..validation import InvalidInputError

__all__ = ["ALIGN_KINDS", "Warp", "estimate_warp", "warp_image", "align_target", "align_source", "match_photometry"]

#: The warp models, by number of parameters.
ALIGN_KINDS = {"translation": 2, "similarity": 4, "affine": 6}

#: Gaussian blur (pixels) of the coarse-to-fine estimation levels. The finest level
#: still smooths by one pixel: on unsmoothed images, sampling the noisy target between
#: pixels averages its noise and lowers the loss, which pulls the warp off the truth.
#: On data_synthetic/fran_front against the true prediction, stopping at 0 gave a
#: similarity of scale 0.99976 and a shift of 0.02 px (0.05 px at the mask's edge);
#: stopping at 1 gave scale 1.000001 and a shift below 0.001 px.
_LEVELS = (3.0, 1.0)


@dataclasses.dataclass(frozen=True)
class Warp:
    """A fitted warp from source pixels to target pixels (see the module docstring).

    Examples
    --------
    >>> warp = Warp("similarity", (1.0, -2.0, float(np.radians(1.0)), 0.0), (50.0, 60.0))
    >>> [round(float(v), 3) for v in warp.matrix().ravel()]
    [1.0, -0.017, 0.017, 1.0]
    >>> warp.map_points(np.array([[50.0, 60.0]])).tolist()  # the centre only moves by t
    [[51.0, 58.0]]
    """

    kind: str
    params: tuple
    centre: tuple

    def matrix(self) -> np.ndarray:
        return _matrix(self.kind, np.asarray(self.params, np.float64), np)

    def map_points(self, points: np.ndarray) -> np.ndarray:
        """Source (row, col) points (N, 2) to target positions (N, 2)."""
        c = np.asarray(self.centre)
        return (points - c) @ self.matrix().T + c + np.asarray(self.params[:2])

    def inverse_map_points(self, points: np.ndarray) -> np.ndarray:
        """Target (row, col) points (N, 2) to the source positions that land there."""
        c = np.asarray(self.centre)
        return (points - c - np.asarray(self.params[:2])) @ np.linalg.inv(self.matrix()).T + c

    def recentred(self, centre) -> Warp:
        """The same map written about another ``centre`` (row, col).

        A camera rolls and zooms about its principal point, not about the skin
        mask's centre, so a warp is recentred on the image centre before it is
        turned into a camera move: ``t' = t + (I - A)(c - c')``.

        Examples
        --------
        >>> warp = Warp("similarity", (1.0, -2.0, float(np.radians(1.0)), 0.01), (50.0, 60.0))
        >>> moved = warp.recentred((63.5, 63.5))
        >>> points = np.array([[0.0, 0.0], [100.0, 20.0]])
        >>> bool(np.allclose(moved.map_points(points), warp.map_points(points)))
        True
        """
        c, new = np.asarray(self.centre, np.float64), np.asarray(centre, np.float64)
        shift = np.asarray(self.params[:2]) + (np.eye(2) - self.matrix()) @ (c - new)
        return Warp(self.kind, tuple(float(v) for v in shift) + tuple(self.params[2:]),
                    tuple(float(v) for v in new))

    def to_dict(self) -> dict:
        """JSON-ready: the kind, the shift (px), rotation (deg), scale and the 2x3 matrix."""
        a = self.matrix()
        out: dict[str, Any] = {"kind": self.kind, "shift_px": [float(v) for v in self.params[:2]],
               "centre_px": [float(v) for v in self.centre]}
        if self.kind == "similarity":
            out["rotation_deg"] = float(np.degrees(self.params[2]))
            out["scale"] = float(np.exp(self.params[3]))
        out["matrix"] = np.concatenate([a, np.asarray(self.params[:2])[:, None]], axis=1).tolist()
        return out


    @classmethod
    def from_dict(cls, record: dict) -> Warp:
        """The warp written by :meth:`to_dict` (a params.json ``alignment`` entry)."""
        kind, shift = record["kind"], list(record["shift_px"])
        if kind == "translation":
            params = shift
        elif kind == "similarity":
            params = shift + [float(np.radians(record["rotation_deg"])), float(np.log(record["scale"]))]
        else:
            a = np.asarray(record["matrix"], np.float64)[:, :2] - np.eye(2)
            params = shift + a.ravel().tolist()
        return cls(kind, tuple(float(v) for v in params), tuple(record["centre_px"]))


def _matrix(kind, p, xp=jnp):
    """The 2x2 part of the warp, with NumPy or jax.numpy (``xp``)."""
    if kind == "translation":
        return xp.eye(2, dtype=p.dtype)
    if kind == "similarity":
        s, th = xp.exp(p[3]), p[2]
        return s * xp.stack([xp.stack([xp.cos(th), -xp.sin(th)]), xp.stack([xp.sin(th), xp.cos(th)])])
    return xp.eye(2, dtype=p.dtype) + p[2:].reshape(2, 2)


def _coordinates(kind, p, centre, shape):
    rows, cols = jnp.meshgrid(jnp.arange(shape[0], dtype=p.dtype), jnp.arange(shape[1], dtype=p.dtype),
                              indexing="ij")
    x = jnp.stack([rows - centre[0], cols - centre[1]], axis=-1)
    mapped = x @ _matrix(kind, p).T + centre + p[:2]
    return mapped[..., 0], mapped[..., 1]


def _bilinear(image, r, c):
    """``image`` (H, W, C) at real positions; edge values outside (the mask drops them)."""
    return jnp.stack([jax.scipy.ndimage.map_coordinates(image[..., k], [r, c], order=1, mode="nearest")
                      for k in range(image.shape[-1])], axis=-1)


def _residual(p, args):
    kind, moving, reference, weight, centre = args
    r, c = _coordinates(kind, p, centre, reference.shape[:2])
    sampled = _bilinear(moving, r, c)
    # No down-weighting of samples that fall outside the image (edge values are
    # used): a weight that depends on the warp lets the solver lower the loss by
    # pushing pixels out of the frame.
    w = weight
    # Gain and offset per channel in closed form: exposure differences do not move the warp.
    sw = jnp.sum(w) + 1e-12
    mean_s = jnp.sum(w[..., None] * sampled, axis=(0, 1)) / sw
    mean_r = jnp.sum(w[..., None] * reference, axis=(0, 1)) / sw
    ds, dr = sampled - mean_s, reference - mean_r
    gain = jnp.sum(w[..., None] * ds * dr, axis=(0, 1)) / (jnp.sum(w[..., None] * ds * ds, axis=(0, 1)) + 1e-12)
    return (jnp.sqrt(w)[..., None] * (gain * ds - dr)).ravel()


def _solve(kind, moving, reference, weight, centre, p0):
    solver = optx.LevenbergMarquardt(rtol=1e-7, atol=1e-9)
    args = (kind, jnp.asarray(moving), jnp.asarray(reference), jnp.asarray(weight), jnp.asarray(centre))
    solution = optx.least_squares(_residual, solver, jnp.asarray(p0), args=args, max_steps=200, throw=False)
    return np.asarray(solution.value, np.float64)


def match_photometry(image: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``image`` (H, W, C) mapped to ``reference``'s channels (H, W, C') by least squares on ``mask``.

    Each reference channel gets an affine combination of the image's channels (an
    RGB -> grey mix for a grey reference), so source and photograph can be compared.
    """
    on = mask > 0
    design = np.concatenate([image[on], np.ones((int(on.sum()), 1))], axis=1)
    coef, *_ = np.linalg.lstsq(design, reference[on], rcond=None)
    flat = np.concatenate([image.reshape(-1, image.shape[-1]), np.ones((image[..., 0].size, 1))], axis=1)
    return (flat @ coef).reshape(image.shape[:2] + (reference.shape[-1],))


def _phase_shift(moving, reference, weight) -> np.ndarray:
    """Translation (rows, cols) of ``moving`` relative to ``reference`` by phase correlation."""
    from skimage.registration import phase_cross_correlation

    a = (reference.mean(axis=-1) - reference.mean()) * weight
    b = (moving.mean(axis=-1) - moving.mean()) * weight
    shift, _, _ = phase_cross_correlation(a, b, upsample_factor=4, normalization=None)
    return -np.asarray(shift, np.float64)


def estimate_warp(moving, reference, mask, kind: str = "similarity", start: Warp | None = None) -> Warp:
    """The warp that best maps ``reference``'s pixels into ``moving`` (both (H, W, C), same C).

    Parameters
    ----------
    moving : array, shape (H, W, C)
        The image to be resampled (the target photograph).
    reference : array, shape (H, W, C)
        The image on the grid to resample onto (source side), photometrically
        matched to ``moving`` up to a gain and offset per channel.
    mask : array, shape (H, W)
        Where to compare (the skin mask).
    kind : {"translation", "similarity", "affine"}
    start : Warp, optional
        Where to start; by default a phase-correlation shift.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> reference = ndimage.gaussian_filter(rng.uniform(size=(64, 64)), 2.0)[..., None]
    >>> moving = ndimage.shift(reference, (1.5, -2.25, 0.0), order=3)
    >>> mask = np.zeros((64, 64)); mask[8:56, 8:56] = 1.0  # away from the frame's edges
    >>> warp = estimate_warp(moving, reference, mask, "translation")
    >>> bool(np.allclose(warp.params, (1.5, -2.25), atol=0.01))  # within a hundredth of a pixel
    True
    """
    if kind not in ALIGN_KINDS:
        raise InvalidInputError(f"align: expected one of none, {', '.join(ALIGN_KINDS)}, got {kind!r}", field="align")
    moving = np.asarray(moving, np.float64)
    reference = np.asarray(reference, np.float64)
    weight = (np.asarray(mask) > 0).astype(np.float64)
    rows, cols = np.nonzero(weight)
    centre = (float(rows.mean()), float(cols.mean()))
    p = np.zeros(ALIGN_KINDS[kind])
    if start is not None and start.kind == kind:
        p[:] = start.params
    elif start is not None:
        p[:2] = start.params[:2]
    else:
        p[:2] = _phase_shift(moving, reference, weight)
    with jax.enable_x64(True):
        for sigma in _LEVELS:
            # The blur is applied at once, within this iteration (B023 looks for a late call).
            blur = (lambda im: ndimage.gaussian_filter(im, (sigma, sigma, 0))) if sigma else (lambda im: im)  # noqa: B023
            p = _solve(kind, blur(moving), blur(reference), weight, centre, p)
    return Warp(kind, tuple(float(v) for v in p), centre)


def warp_image(image, warp: Warp, order: int = 3):
    """``image`` (H, W, C) (the target) sampled at the warped source grid (cubic spline by default).

    Returns the resampled image and the (H, W) map of pixels whose warped position
    lies inside ``image`` (edge values are used elsewhere).

    Examples
    --------
    >>> image = np.arange(25.0).reshape(5, 5, 1)
    >>> out, valid = warp_image(image, Warp("translation", (0.0, 1.0), (2.0, 2.0)))
    >>> out[2, :4, 0].round(6).tolist(), valid[2].tolist()
    ([11.0, 12.0, 13.0, 14.0], [True, True, True, True, False])
    """
    image = np.asarray(image, np.float64)
    shape = image.shape[:2]
    positions = warp.map_points(_grid(shape))
    return _sample(image, positions, shape, order), _inside(positions, shape, shape)


def align_target(target, mask, warp: Warp):
    """``target`` ((H, W) or (H, W, C)) on the source's grid, and ``mask`` without the pixels it leaves.

    Examples
    --------
    >>> target, mask = np.arange(16.0).reshape(4, 4), np.ones((4, 4))
    >>> moved, kept = align_target(target, mask, Warp("translation", (1.0, 0.0), (1.5, 1.5)))
    >>> moved[0].round(6).tolist(), kept[:, 0].tolist()
    ([4.0, 5.0, 6.0, 7.0], [1.0, 1.0, 1.0, 0.0])
    """
    target = np.asarray(target, np.float64)
    moved, valid = warp_image(target[..., None] if target.ndim == 2 else target, warp)
    mask = np.ones(target.shape[:2]) if mask is None else np.asarray(mask, np.float64)
    return (moved[..., 0] if target.ndim == 2 else moved), np.where(valid, mask, 0.0)


def _grid(shape) -> np.ndarray:
    """Every pixel's (row, col) of an image of ``shape``, as (N, 2)."""
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return np.stack([rows.ravel(), cols.ravel()], axis=1)


def _inside(positions, frame, shape) -> np.ndarray:
    """Which ``positions`` (N, 2) fall inside an image of size ``frame``, reshaped to ``shape``."""
    eps = 1e-6
    ok = ((positions[:, 0] >= -eps) & (positions[:, 0] <= frame[0] - 1 + eps)
          & (positions[:, 1] >= -eps) & (positions[:, 1] <= frame[1] - 1 + eps))
    return ok.reshape(shape)


def _sample(image, positions, shape, order):
    """``image`` (H, W, C) at ``positions`` (N, 2), reshaped to ``shape`` + (C,); edge values outside."""
    return np.stack([ndimage.map_coordinates(image[..., k], positions.T, order=order, mode="nearest").reshape(shape)
                     for k in range(image.shape[-1])], axis=-1)


def align_source(source, depth, mask, warp: Warp, shape):
    """The source, depth and mask resampled onto the target's grid of ``shape`` (H', W').

    Returns ``(source, depth, mask)``: the source (cubic spline), the depth
    (linear, after its renderer background is filled, see
    :func:`invsss.forward.pair.fill_background_depth`) and the mask (linear), 0 where the
    target pixel comes from outside the source's frame.

    Examples
    --------
    >>> source = np.arange(16.0).reshape(4, 4, 1)
    >>> moved, depth, mask = align_source(source, np.full((4, 4), 500.0), np.ones((4, 4)),
    ...                                   Warp("translation", (1.0, 0.0), (1.5, 1.5)), (4, 4))
    >>> moved[1, :, 0].round(6).tolist(), mask[:, 0].tolist()
    ([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 1.0, 1.0])
    """
    source = np.asarray(source, np.float64)
    source = source[..., None] if source.ndim == 2 else source
    positions = warp.inverse_map_points(_grid(shape))
    inside = _inside(positions, source.shape[:2], shape)
    depth = np.asarray(fill_background_depth(np.asarray(depth, np.float64)), np.float64)
    moved = _sample(source, positions, shape, 3)
    moved_depth = _sample(depth[..., None], positions, shape, 1)[..., 0]
    moved_mask = _sample(np.asarray(mask, np.float64)[..., None], positions, shape, 1)[..., 0]
    return moved, moved_depth, np.where(inside, np.clip(moved_mask, 0.0, 1.0), 0.0)


def align_vectors(vectors, warp: Warp, shape):
    """A buffer of unit vectors (H, W, 3) resampled onto the target's grid, renormalised.

    For the light-aware terms' normal and light buffers (:mod:`invsss.forward.light_terms`):
    linear interpolation, then unit length again. The vectors themselves are not
    rotated with a similarity warp; a rotation of a degree or two turns them by as
    much, far below what the terms resolve. ``None`` passes through.

    Examples
    --------
    >>> v = np.zeros((3, 3, 3)); v[..., 2] = 1.0
    >>> align_vectors(v, Warp("translation", (0.5, 0.0), (1.0, 1.0)), (3, 3))[1, 1].tolist()
    [0.0, 0.0, 1.0]
    """
    if vectors is None:
        return None
    positions = warp.inverse_map_points(_grid(shape))
    moved = _sample(np.asarray(vectors, np.float64), positions, shape, 1)
    length = np.linalg.norm(moved, axis=-1, keepdims=True)
    return np.where(length > 1e-6, moved / np.maximum(length, 1e-12), np.array([0.0, 0.0, 1.0]))
