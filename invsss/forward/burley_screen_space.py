"""The ``burley`` model: Christensen & Burley's normalized diffusion sampled over a disk in screen space.

This is how Unity HDRP and Unreal Engine blur skin (docs/model.md, section 5,
"The burley model"): every skin pixel gathers ``N`` samples of the lit image at
importance-sampled radii around it and weights them by the profile

    R_c(r) = (e^{-r/d_c} + e^{-r/(3 d_c)}) / (8 pi d_c r)

with one shape parameter ``d_c`` (scene units, mm) per channel. A radius of
``r`` scene units covers ``r L / depth`` pixels (``L = sss_level``, the
projection the other models use, without their slope correction).

The sample pattern is fixed, so the model is deterministic and differentiable:

* radii: sample ``j`` of ``N`` sits where the radial CDF of the widest channel
  ``F(r) = 1 - e^{-r/d}/4 - 3 e^{-r/(3d)}/4`` equals ``(j + 1/2) / N``; since
  ``F`` depends on ``r / d`` only, the unit-``d`` radii are constants
  (:func:`unit_radii`, inverted in closed form) and ``r_j = d_max x_j``, so the
  positions move smoothly with ``d``;
* angles: the golden angle ``j pi (3 - sqrt 5)`` (a Vogel / Fibonacci spiral);
* weights: one set of gathers serves every channel (as HDRP does: it importance
  samples the channel with the widest distance); channel ``c`` weights sample
  ``j`` by ``R_c(rho_j) rho_j / pdf_max(r_j)``, the profile at the 3D distance
  ``rho_j = sqrt(r_j^2 + (z_j - z)^2)`` between the pixel and the surface point
  the sample lands on (HDRP's bilateral weight), times the skin mask there;
  the sum is normalised per channel, so the blur keeps energy whatever ``N``.

Images are read with bilinear interpolation and clamp-to-edge addressing, so
gradients reach ``d`` and ``L`` through the sample positions as well as the weights.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..validation import InvalidInputError

__all__ = [
    "BURLEY_SAMPLES",
    "GOLDEN_ANGLE",
    "burley_cdf",
    "unit_radii",
    "sample_pattern",
    "burley_distances",
    "check_burley_distances",
    "sample_bilinear",
    "render_burley",
    "start_variances",
]

#: Samples per pixel of the model's fixed pattern. HDRP's per-quality sample
#: budgets are 20, 40 and 80 (its ``DefaultSssSampleBudgetForQualityLevel``);
#: 32 sits between its Low and Medium budgets.
BURLEY_SAMPLES = 32

#: ``pi (3 - sqrt 5)``: consecutive samples turn by it, so no two line up.
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))

#: The per-axis variance of Burley's profile is ``7 d^2`` (its second moment
#: ``int r^2 R(r) 2 pi r dr = 14 d^2`` over two axes).
BURLEY_VARIANCE_PER_D2 = 7.0


def burley_cdf(x):
    """The radial CDF ``F(x) = 1 - e^{-x}/4 - 3 e^{-x/3}/4`` of the profile at ``x = r / d``.

    Examples
    --------
    >>> round(float(burley_cdf(0.0)), 12), round(float(burley_cdf(50.0)), 6)
    (0.0, 1.0)
    """
    x = np.asarray(x, np.float64)
    return 1.0 - 0.25 * np.exp(-x) - 0.75 * np.exp(-x / 3.0)


def unit_radii(n: int = BURLEY_SAMPLES) -> np.ndarray:
    """The radii ``x_j`` (in units of ``d``) where ``F(x_j) = (j + 1/2) / n``, float64, shape (n,).

    With ``t = e^{-x/3}`` and ``u = 1 - F``, ``F(x) = 1 - u`` reads
    ``t^3 + 3 t - 4 u = 0``, a depressed cubic with one real root (Cardano):
    ``t = cbrt(2u + sqrt(4u^2 + 1)) + cbrt(2u - sqrt(4u^2 + 1))``, ``x = -3 ln t``.

    Examples
    --------
    >>> x = unit_radii(4)
    >>> np.allclose(burley_cdf(x), [0.125, 0.375, 0.625, 0.875])
    True
    """
    if not isinstance(n, int) or isinstance(n, bool) or n < 1:
        raise InvalidInputError(f"samples: expected an integer >= 1, got {n!r}")
    u = 1.0 - (np.arange(n, dtype=np.float64) + 0.5) / n
    root = np.sqrt(4.0 * u * u + 1.0)
    t = np.cbrt(2.0 * u + root) + np.cbrt(2.0 * u - root)
    return -3.0 * np.log(t)


def sample_pattern(n: int = BURLEY_SAMPLES) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x, cos, sin)``, each shape (n,): unit-``d`` radii and the golden-angle directions.

    Examples
    --------
    >>> x, c, s = sample_pattern(3)
    >>> np.allclose(c**2 + s**2, 1.0), bool(np.all(np.diff(x) > 0))
    (True, True)
    """
    x = unit_radii(n)
    angle = GOLDEN_ANGLE * np.arange(n, dtype=np.float64)
    return x, np.cos(angle), np.sin(angle)


def check_burley_distances(variances, channels: int, name: str = "params") -> None:
    """Raise unless ``variances`` holds one value, or one per image channel (shapes only).

    For ``burley`` the K entries of :attr:`invsss.SSSParams.variances` are the
    squared shape parameters ``d_c^2`` (mm^2), so that the estimator's gauge and
    log reparametrisation apply unchanged (docs/model.md, section 5).
    """
    k = int(np.shape(variances)[-1])
    if k not in (1, channels):
        raise InvalidInputError(
            f"{name}.variances: the burley model takes d^2 for one channel or for each of the image's "
            f"{channels} channels, got {k} values",
            field=f"{name}.variances",
        )


def burley_distances(variances, channels: int) -> Float[Array, " C"]:
    """The shape parameters ``d_c = sqrt(v_c)`` broadcast to ``channels``, shape (C,)."""
    check_burley_distances(variances, channels)
    d = jnp.sqrt(jnp.asarray(variances))
    return jnp.broadcast_to(d, (channels,))


def sample_bilinear(
    image: Float[Array, "H W C"], y: Float[Array, "H W"], x: Float[Array, "H W"]
) -> Float[Array, "H W C"]:
    """``image`` read at real coordinates ``(y, x)`` per output pixel: bilinear, clamp-to-edge.

    Coordinates are clamped to ``[0, n - 1]`` (no gradient flows through a
    clamped one); four gathers from the flattened image, indices in bounds by
    construction. Images of one row or column are read along the other axis.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> img = jnp.arange(6.0).reshape(2, 3, 1)
    >>> float(sample_bilinear(img, jnp.full((1, 1), 0.5), jnp.full((1, 1), 1.5))[0, 0, 0])
    3.0
    """
    h, w, c = image.shape
    yc = jnp.clip(y, 0.0, h - 1.0)
    xc = jnp.clip(x, 0.0, w - 1.0)
    y0 = jnp.clip(jnp.floor(yc).astype(jnp.int32), 0, max(h - 2, 0))
    x0 = jnp.clip(jnp.floor(xc).astype(jnp.int32), 0, max(w - 2, 0))
    fy = (yc - y0)[..., None]
    fx = (xc - x0)[..., None]
    dy = 1 if h > 1 else 0
    dx = 1 if w > 1 else 0
    flat = image.reshape(h * w, c)
    top = y0 * w + x0
    get = lambda idx: flat.at[idx].get(mode="promise_in_bounds")  # noqa: E731
    a, b = get(top), get(top + dx)
    cc, dd = get(top + dy * w), get(top + dy * w + dx)
    upper = a + fx * (b - a)
    lower = cc + fx * (dd - cc)
    return upper + fy * (lower - upper)


def _profile_weight(rho, r, d, d_max):
    """``R_c(rho) rho / pdf_max(r)`` up to a factor common to every sample: (H, W, C).

    ``R_c(rho) rho = (e^{-rho/d_c} + e^{-rho/(3 d_c)}) / (8 pi d_c)`` and the
    radial pdf of the widest channel is ``(e^{-r/d_m} + e^{-r/(3 d_m)}) / (4 d_m)``.
    """
    rho = rho[..., None]
    numerator = (jnp.exp(-rho / d) + jnp.exp(-rho / (3.0 * d))) / d
    denominator = (jnp.exp(-r / d_max) + jnp.exp(-r / (3.0 * d_max))) / d_max
    return numerator / denominator


def render_burley(
    image: Float[Array, "H W C"],
    depth: Float[Array, "H W"],
    mask: Float[Array, "H W"],
    params,
    tap_w=None,
    samples: int = BURLEY_SAMPLES,
) -> Float[Array, "H W C"]:
    """The ``burley`` model's blur of ``image`` (see the module docstring).

    Parameters
    ----------
    image : array, shape (H, W, C)
    depth : array, shape (H, W)
        Eye-space depth, scene units (> 0).
    mask : array, shape (H, W)
        Skin (1) or not (0); samples off the mask get no weight, and
        ``out = I + m (blurred - I)``.
    params : SSSParams
        ``sss_level`` (pixels per scene unit at unit depth) and ``variances``
        (``d_c^2``, one or C of them); the other fields are not used.
    tap_w : ignored
        The other layouts' tap weights (this layout has none).
    samples : int
        Samples per pixel (default :data:`BURLEY_SAMPLES`).

    Returns
    -------
    array, shape (H, W, C)

    Examples
    --------
    >>> import jax.numpy as jnp, invsss
    >>> p = invsss.SSSParams(1000.0, 0.0, 1.0, [1.0], [0.25])
    >>> out = render_burley(jnp.ones((8, 8, 3)), jnp.full((8, 8), 500.0), jnp.ones((8, 8)), p)
    >>> bool(jnp.allclose(out, 1.0))
    True
    """
    h, w, c = image.shape
    dtype = image.dtype
    d = burley_distances(params.variances, c).astype(dtype)
    d_max = jnp.max(d)
    x_unit, cos_a, sin_a = (jnp.asarray(a, dtype) for a in sample_pattern(samples))
    # Pixels per scene unit at each pixel: the projection of the other models, no slope term.
    scale = params.sss_level.astype(dtype) / depth
    ys = jnp.arange(h, dtype=dtype)[:, None] * jnp.ones((1, w), dtype)
    xs = jnp.arange(w, dtype=dtype)[None, :] * jnp.ones((h, 1), dtype)
    # Image, mask and depth are read at the same positions: one gather each corner.
    stacked = jnp.concatenate([image, mask[..., None], depth[..., None]], axis=-1)

    # One sample per scan step: each step's gathers fuse into the running sums,
    # and compile time does not grow with the sample count.
    @jax.checkpoint
    def step(carry, xs_j):
        total, weight_sum = carry
        x_j, cos_j, sin_j = xs_j
        r = d_max * x_j  # scene units
        radius_px = r * scale
        read = sample_bilinear(stacked, ys + radius_px * sin_j, xs + radius_px * cos_j)
        value, on_skin, z = read[..., :c], read[..., c], read[..., c + 1]
        rho = jnp.sqrt(r * r + (z - depth) ** 2)
        weight = _profile_weight(rho, r, d, d_max) * on_skin[..., None]
        return (total + weight * value, weight_sum + weight), None

    zeros = jnp.zeros_like(image)
    (total, weight_sum), _ = jax.lax.scan(step, (zeros, zeros), (x_unit, cos_a, sin_a))
    # A pixel whose samples all land off the skin keeps its own value.
    some = weight_sum > 0
    blurred = jnp.where(some, total / jnp.where(some, weight_sum, 1.0), image)
    return image + mask[..., None] * (blurred - image)


def start_variances(profile_weights, profile_variances, channels: int) -> np.ndarray:
    """Where the estimator starts ``d_c^2`` from a sum-of-Gaussians profile: shape (channels,).

    Matches the per-axis variance: the profile's ``sum_i w_ic v_i`` (weights
    normalised per channel) equals Burley's ``7 d_c^2``; a profile with one
    weight column per channel gives each channel its own start.

    Examples
    --------
    >>> start_variances(np.array([0.5, 0.5]), np.array([7.0, 21.0]), 3).tolist()
    [2.0, 2.0, 2.0]
    """
    w = np.asarray(profile_weights, np.float64)
    v = np.asarray(profile_variances, np.float64)
    w = w.reshape(w.shape[0], -1) / np.sum(w.reshape(w.shape[0], -1), axis=0)  # (K, 1 or C')
    per_axis = np.sum(w * v[:, None], axis=0)  # (1 or C',)
    if per_axis.size not in (1, channels):
        per_axis = np.array([per_axis.mean()])
    return np.broadcast_to(per_axis / BURLEY_VARIANCE_PER_D2, (channels,)).copy()
