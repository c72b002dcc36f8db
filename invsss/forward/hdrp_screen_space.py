"""What Unity HDRP's screen-space subsurface scattering shows for a ``burley`` fit (issue 46).

The ``burley`` model (:mod:`invsss.forward.burley_screen_space`, docs/model.md
section 5) is HDRP's blur with the engine's per-pixel choices taken out: a fixed
pattern of 32 samples, read with bilinear interpolation, the same for every pixel.
:func:`render_hdrp_like` puts those choices back, as HDRP's published code makes
them, so that the gap between the fitted image and what the engine draws can be
measured (``experiments/engine_gap.py``, docs/renderer.md "What HDRP will show").
It is NumPy in float64 and not differentiable: it is for measuring, not fitting.

The rules, each with the HDRP source it was read from (Unity-Technologies/Graphics,
``com.unity.render-pipelines.high-definition``; the code was read, not copied):

1. **Sample count from the footprint** (``Runtime/Material/SubsurfaceScattering/
   SubsurfaceScattering.compute``, ``EvaluateSss``; the radius from
   ``Runtime/Material/DiffusionProfile/DiffusionProfileSettings.cs``,
   ``DiffusionProfile.UpdateKernel``): the profile's filter radius is where the
   widest channel's radial CDF reaches 99.7 %, ``R = x_997 d_max``; a pixel that sees
   ``p = sss_level / depth`` pixels per mm asks for ``floor(pi (R p)^2 / 4)`` samples
   (one per 4 pixels of the disk, ``SSS_PIXELS_PER_SAMPLE``) and takes
   ``n = min(that, budget)``; when it asks for none, the pixel is not blurred.
   The budget is the quality setting (``DefaultSssSampleBudgetForQualityLevel``:
   20, 40, 80 and 1000 for Low, Medium, High and Max, :data:`QUALITY_LEVELS`).
2. **Radii for that count** (``EvaluateSample`` with ``SampleBurleyDiffusionProfile``
   of ``DiffusionProfile.hlsl``): sample ``i`` of ``n`` sits at the radial quantile
   ``(i + 1/2) / n`` of the widest channel, the radii of the ``burley`` model for
   ``N = n`` (:func:`~invsss.forward.burley_screen_space.unit_radii`).
3. **Golden-angle directions, rotated per pixel** (``EvaluateSample`` with
   ``SampleDiskGolden`` of the core library's ``Sampling/Fibonacci.hlsl``; the phase
   from ``GenerateHashedRandomFloat`` of ``ShaderLibrary/Random.hlsl``): sample ``i``
   turns by ``2 pi frac(i / golden ratio)`` (the mirror image of the ``burley``
   model's golden angle, which turns the other way) plus a phase per pixel,
   ``2 pi`` times a Jenkins one-at-a-time hash of ``(x, y, key)`` read as a float in
   [0, 1) from its low 23 bits. HDRP's key is the pixel's device depth times
   ``2^24``, which depends on the camera's near and far planes (not known here)
   and changes with TAA's sub-pixel jitter; here ``seed + frame`` stands in for it.
4. **Whole pixels** (``EvaluateSample``, ``LoadSample``): a sample's offset
   ``p r (cos, sin)`` is rounded to whole pixels and that pixel is read as it is
   (no interpolation); a sample beyond the image reads nothing (out-of-range loads
   return 0, which fails ``TestLightingForSSS``) instead of the border pixel.
5. **Weights** (``ComputeBilateralWeight``, ``EvalBurleyDiffusionProfile``): the
   ``burley`` model's, ``R_c(rho) rho / pdf(r)`` at the 3D distance ``rho`` between
   the pixel's point and the sample's, with ``r`` the sample's nominal radius (not
   the rounded one); a sample off the skin gets none; the sum is normalised per
   channel and a pixel that gathered nothing becomes 0. ``S = 1 / d`` is clamped to
   ``2^24`` (``UpdateKernel``), so ``d`` is at least ``2^-24`` mm.
6. **Max quality reads far samples from a downsampled image** (the current
   sources, under ``Packages/``; the earlier ones have no downsampling: ``USE_DOWNSAMPLE``
   in ``SubsurfaceScattering.compute``'s ``LoadSample``,
   ``RandomDownsample.compute``, ``DefaultSssDownsampleSteps``): the pass runs in
   tiles of 16 x 16 pixels, each of which first copies its pixels and a border of
   2 (20 x 20) at full resolution into a cache; a sample inside its tile's cache
   reads it there, any other sample reads the lit image from a copy ``2^s`` times
   smaller per axis (``s = downsample_steps``), each of whose pixels is one pixel of
   its ``2^s x 2^s`` block, picked by Jimenez's interleaved gradient noise of the
   frame. Depth is always read at full resolution.

Not modelled: the material's subsurface mask (scaling the distances per pixel;
taken as 1), the split of the lit image into albedo and irradiance (HDRP blurs
irradiance and multiplies the albedo after; the image here is blurred as a whole,
as in the ``burley`` model), float32 arithmetic, and temporal anti-aliasing beyond
a plain mean over ``frames`` (TAA's history blend and clamping are not modelled).
Whether the pattern's turning sense matches the image's rows depends on the
graphics API's vertical convention, which was not established; with the per-pixel
rotation on, the mirror changes nothing on average.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from ..validation import InvalidInputError, check_depth, check_image, check_mask, number_array
from .burley_screen_space import unit_radii
from .pair import fill_background_depth

__all__ = [
    "QUALITY_LEVELS",
    "FILTER_RADIUS_CDF",
    "PIXELS_PER_SAMPLE",
    "filter_radius",
    "sample_counts",
    "rotation_phases",
    "gradient_noise",
    "downsampled",
    "in_cache",
    "render_hdrp_like",
]

#: HDRP's quality levels: ``(sample budget, downsample steps)``
#: (``DefaultSssSampleBudgetForQualityLevel`` and ``DefaultSssDownsampleSteps`` in
#: ``DiffusionProfileSettings.cs``; the downsampling is in the current sources only).
QUALITY_LEVELS = {"low": (20, 0), "medium": (40, 0), "high": (80, 0), "max": (1000, 2)}

#: The share of the widest channel's energy inside the filter radius (``UpdateKernel``).
FILTER_RADIUS_CDF = 0.997

#: Pixels of the filter's disk per sample (``SSS_PIXELS_PER_SAMPLE``).
PIXELS_PER_SAMPLE = 4

#: ``Golden2dSeq``'s ratio: sample ``i`` turns by ``2 pi frac(i / GOLDEN_RATIO)``.
GOLDEN_RATIO = (1.0 + math.sqrt(5.0)) / 2.0

#: The pass's tiles (``GROUP_SIZE_1D``) and the border its cache holds around each
#: (``TEXTURE_CACHE_BORDER``), in pixels.
TILE, CACHE_BORDER = 16, 2

#: The smallest distance HDRP keeps (its shape parameter ``1 / d`` is clamped to 2^24).
MIN_DISTANCE_MM = 2.0**-24


def _unit_quantile(cdf: float) -> float:
    """``x`` (in units of ``d``) where Burley's radial CDF equals ``cdf``: the closed
    form of :func:`~invsss.forward.burley_screen_space.unit_radii` for one value."""
    u = 1.0 - cdf
    root = math.sqrt(4.0 * u * u + 1.0)
    return -3.0 * math.log(np.cbrt(2.0 * u + root) + np.cbrt(2.0 * u - root))


def filter_radius(d_max) -> float:
    """HDRP's filter radius in mm: where the widest channel holds 99.7 % of its energy.

    Examples
    --------
    >>> round(filter_radius(1.0), 3)
    16.564
    """
    return _unit_quantile(FILTER_RADIUS_CDF) * float(d_max)


def sample_counts(depth, d_max, sss_level, budget: int, footprint: bool = True) -> np.ndarray:
    """Samples per pixel, int, shape (H, W): ``min(floor(pi (R p)^2 / 4), budget)``.

    ``p = sss_level / depth`` is the pixel's pixels per mm and ``R`` the
    :func:`filter_radius` of ``d_max``; 0 means the pixel is not blurred. With
    ``footprint=False`` every pixel takes ``budget`` (the ``burley`` model's rule).

    Examples
    --------
    >>> sample_counts(np.array([[500.0, 1000.0, 4000.0]]), 0.7, 400.0, 40).tolist()
    [[40, 16, 1]]
    """
    depth = np.asarray(depth, np.float64)
    if not footprint:
        return np.full(depth.shape, budget, np.int64)
    radius_px = filter_radius(d_max) * float(sss_level) / depth
    wanted = np.floor(math.pi * radius_px**2 / PIXELS_PER_SAMPLE)
    return np.minimum(wanted, budget).astype(np.int64)


def _jenkins(x: np.ndarray) -> np.ndarray:
    """One round of Bob Jenkins' one-at-a-time hash on uint32 (wrapping) arithmetic."""
    x = x.astype(np.uint32)
    x = x + (x << np.uint32(10))
    x = x ^ (x >> np.uint32(6))
    x = x + (x << np.uint32(3))
    x = x ^ (x >> np.uint32(11))
    return x + (x << np.uint32(15))


def rotation_phases(height: int, width: int, key: int) -> np.ndarray:
    """The per-pixel phase in [0, 2 pi), shape (height, width), from ``key`` (uint32).

    HDRP hashes ``(x, y, key)`` as ``H(x ^ H(y ^ H(key)))`` with ``H`` the
    one-at-a-time round and reads the low 23 bits as a fraction of 1.

    Examples
    --------
    >>> phase = rotation_phases(4, 5, 0)
    >>> phase.shape, bool(np.all((phase >= 0) & (phase < 2 * np.pi)))
    ((4, 5), True)
    """
    rows, cols = np.mgrid[0:height, 0:width].astype(np.uint32)
    inner = _jenkins(np.full((height, width), key % 2**32, np.uint32))
    hashed = _jenkins(cols ^ _jenkins(rows ^ inner))
    return 2.0 * math.pi * (hashed & np.uint32(0x7FFFFF)).astype(np.float64) / 2.0**23


def gradient_noise(rows: np.ndarray, cols: np.ndarray, frame: int) -> np.ndarray:
    """Jimenez's interleaved gradient noise of pixel ``(cols, rows)`` at ``frame``, in [0, 1)."""
    x = cols + 2.083 * frame
    y = rows + 4.867 * frame
    inner = np.mod(0.06711056 * x + 0.00583715 * y, 1.0)
    return np.mod(52.9829189 * inner, 1.0)


def downsampled(stack: np.ndarray, steps: int, frame: int) -> np.ndarray:
    """One pixel of every ``2^steps`` block, picked by gradient noise: shape (h', w', k).

    The pick ``index`` in ``[0, 4^steps)`` moves ``index // 2^steps`` pixels along x and
    ``index % 2^steps`` along y. A pick beyond the image reads zeros (mask 0 too).
    """
    scale = 1 << steps
    h, w, k = stack.shape
    rows, cols = np.mgrid[0:-(-h // scale), 0:-(-w // scale)].astype(np.float64)
    index = (gradient_noise(rows, cols, frame) * scale * scale).astype(np.int64)
    src_r = rows.astype(np.int64) * scale + index % scale
    src_c = cols.astype(np.int64) * scale + index // scale
    inside = (src_r < h) & (src_c < w)
    out = stack[np.minimum(src_r, h - 1), np.minimum(src_c, w - 1)]
    return out * inside[..., None]


def in_cache(rows, cols, y, x) -> np.ndarray:
    """Whether sample pixel ``(y, x)`` lies in the cache of the tile of pixel ``(rows, cols)``:
    the tile's 16 x 16 pixels and 2 more on every side."""
    top = (rows // TILE) * TILE - CACHE_BORDER
    left = (cols // TILE) * TILE - CACHE_BORDER
    size = TILE + 2 * CACHE_BORDER
    return (y >= top) & (y < top + size) & (x >= left) & (x < left + size)


def _bilinear(stack: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``stack`` (H, W, K) at real ``(y, x)`` (N,): bilinear, clamp-to-edge, shape (N, K).

    The NumPy form of :func:`~invsss.forward.burley_screen_space.sample_bilinear`
    (the same clamping), so that this module stays in float64 without JAX.
    """
    h, w, _ = stack.shape
    yc, xc = np.clip(y, 0.0, h - 1.0), np.clip(x, 0.0, w - 1.0)
    y0 = np.clip(np.floor(yc).astype(np.int64), 0, max(h - 2, 0))
    x0 = np.clip(np.floor(xc).astype(np.int64), 0, max(w - 2, 0))
    fy, fx = (yc - y0)[:, None], (xc - x0)[:, None]
    y1, x1 = y0 + (1 if h > 1 else 0), x0 + (1 if w > 1 else 0)
    upper = stack[y0, x0] + fx * (stack[y0, x1] - stack[y0, x0])
    lower = stack[y1, x0] + fx * (stack[y1, x1] - stack[y1, x0])
    return upper + fy * (lower - upper)


def _weights(rho: np.ndarray, r: np.ndarray, d: np.ndarray, d_max: float) -> np.ndarray:
    """``R_c(rho) rho / pdf(r)`` per channel, shape (N, C), up to a common factor.

    HDRP's ``EvalBurleyDiffusionProfile(rho, 1/d_c)`` is ``(e^{-rho/(3 d_c)} + e^{-rho/d_c}) / (8 pi d_c)``
    and ``SampleBurleyDiffusionProfile``'s reciprocal pdf ``8 pi d_max / (e^{-r/(3 d_max)} + e^{-r/d_max})``.
    """
    rho = rho[:, None]
    numerator = (np.exp(-rho / d) + np.exp(-rho / (3.0 * d))) / d
    denominator = (np.exp(-r / d_max) + np.exp(-r / (3.0 * d_max))) / d_max
    return numerator / denominator[:, None]


def _check_int(value, name: str, low: int, hint: str = "") -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        raise InvalidInputError(f"{name}: expected an integer >= {low}{hint}, got {value!r}", field=name)
    return int(value)


def _check_inputs(image, depth, mask, d_mm, sss_level, options) -> tuple:
    """The checked, float64 inputs: image (H, W, C), depth, mask, d (C,) and ``L``."""
    check_image(image)
    hw = tuple(np.shape(image)[:2])
    check_mask(mask, hw)
    check_depth(depth, hw, mask=mask)
    image = np.asarray(image, np.float64)
    image = image[..., None] if image.ndim == 2 else image
    channels = image.shape[-1]
    d = number_array(d_mm, "d_mm", "render_hdrp_like").reshape(-1)
    if d.size not in (1, channels):
        raise InvalidInputError(f"d_mm: expected one distance or one per image channel ({channels}), "
                                f"got {d.size} values")
    if not np.all(np.isfinite(d)) or np.any(d < 0):
        raise InvalidInputError(f"d_mm: expected finite distances >= 0 in mm, got {d.tolist()}")
    level = number_array(sss_level, "sss_level", "render_hdrp_like")
    if level.ndim != 0 or not (np.isfinite(level) and level > 0):
        raise InvalidInputError(f"sss_level: expected one finite number > 0 (pixels per mm at unit depth), "
                                f"got {np.asarray(level).tolist()}")
    _check_int(options["budget"], "budget", 1, " (HDRP's quality levels: 20, 40, 80, 1000)")
    _check_int(options["downsample_steps"], "downsample_steps", 0)
    _check_int(options["frames"], "frames", 1)
    _check_int(options["seed"], "seed", 0)
    for switch in ("footprint", "snap", "rotate"):
        if not isinstance(options[switch], bool):
            raise InvalidInputError(f"{switch}: expected True or False, got {options[switch]!r}", field=switch)
    if options["downsample_steps"] and not options["snap"]:
        raise InvalidInputError("downsample_steps: HDRP reads the downsampled image at whole pixels; "
                                "it needs snap=True")
    depth = np.asarray(fill_background_depth(np.asarray(depth, np.float64)), np.float64)
    d = np.maximum(np.broadcast_to(d, (channels,)), MIN_DISTANCE_MM)
    return image, depth, np.asarray(mask, np.float64), d, float(level)


def render_hdrp_like(
    image,
    depth,
    mask,
    d_mm,
    sss_level,
    *,
    budget: int = 40,
    footprint: bool = True,
    snap: bool = True,
    rotate: bool = True,
    downsample_steps: int = 0,
    frames: int = 1,
    seed: int = 0,
) -> np.ndarray:
    """The image HDRP's subsurface-scattering pass would draw for Burley distances ``d_mm``.

    The rules and their sources are in the module docstring; each of the switches
    turns one off. With ``footprint=False``, ``snap=False``, ``rotate=False`` and
    ``budget=32`` it is the ``burley`` model's blur of the image with its rows
    flipped, flipped back: the two patterns turn in opposite senses.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear lit image (the source the fit blurred).
    depth : array, shape (H, W)
        Eye-space depth in mm, > 0 on the mask (the background is filled as in
        :func:`invsss.render`).
    mask : array, shape (H, W)
        Skin in [0, 1]; a sample's weight is multiplied by the mask where it lands
        (HDRP's stencil test, for a 0/1 mask) and ``out = I + m (blurred - I)``.
    d_mm : float or array, shape (C,)
        Burley's shape parameter ``d`` per channel in mm (HDRP's scattering distance
        times its multiplier): for a ``burley`` fit, ``sqrt(variances)``.
    sss_level : float
        Pixels per mm at unit depth: the camera's focal length in pixels.
    budget : int
        HDRP's sample budget, 20, 40, 80 or 1000 for its quality levels
        (:data:`QUALITY_LEVELS`); any integer >= 1 is taken.
    footprint : bool
        Rule 1: the count from the footprint, capped by ``budget``, and no blur
        where it is 0. False: ``budget`` samples everywhere.
    snap : bool
        Rule 4: whole-pixel reads, nothing beyond the border. False: bilinear reads
        with clamp-to-edge addressing, as the ``burley`` model.
    rotate : bool
        Rule 3's per-pixel phase. False: phase 0 everywhere.
    downsample_steps : int
        Rule 6: samples beyond the tile's cache read an image ``2^s`` times smaller;
        the current sources' Max quality uses 2. Needs ``snap``.
    frames : int
        The mean of this many frames, each with its own key (``seed + frame``) for
        the phases and the downsampling: TAA's ideal limit. 1: one frame.
    seed : int
        The key of the first frame.

    Returns
    -------
    ndarray, float64, the shape of ``image``

    Raises
    ------
    InvalidInputError
        A bad image, depth or mask (as :func:`invsss.render`), a ``d_mm`` that is
        not one or C finite values >= 0, an ``sss_level`` that is not > 0, a budget,
        frame count, seed or step count that is not an integer in range, a switch
        that is not a bool, or ``downsample_steps`` without ``snap``.

    Examples
    --------
    >>> import numpy as np
    >>> image = np.ones((16, 16)); depth = np.full((16, 16), 500.0); mask = np.ones((16, 16))
    >>> out = render_hdrp_like(image, depth, mask, 0.7, 400.0, budget=20)
    >>> out.shape, bool(np.allclose(out, 1.0))
    ((16, 16), True)
    """
    options = {"budget": budget, "footprint": footprint, "snap": snap, "rotate": rotate,
               "downsample_steps": downsample_steps, "frames": frames, "seed": seed}
    squeeze = np.ndim(image) == 2
    image, depth, mask, d, level = _check_inputs(image, depth, mask, d_mm, sss_level, options)
    counts = sample_counts(depth, float(np.max(d)), level, budget, footprint) * (mask > 0)
    out = np.zeros_like(image)
    for frame in range(frames):
        out += _one_frame(image, depth, mask, d, level, counts, options, seed + frame)
    out /= frames
    return out[..., 0] if squeeze else out


def _one_frame(image, depth, mask, d, level, counts, options, key) -> np.ndarray:
    """One frame of the pass: every skin pixel with a count gathers its samples."""
    h, w, c = image.shape
    d_max = float(np.max(d))
    rows, cols = np.nonzero(counts > 0)
    n = counts[rows, cols]
    ppm = level / depth[rows, cols]
    z0 = depth[rows, cols]
    phase = rotation_phases(h, w, key)[rows, cols] if options["rotate"] else np.zeros(rows.size)
    stack = np.concatenate([image, mask[..., None]], axis=-1)
    steps = options["downsample_steps"]
    coarse = downsampled(stack, steps, key) if steps else stack
    radii = np.zeros((int(n.max(initial=0)) + 1, int(n.max(initial=0))))
    for count in np.unique(n):
        radii[count, :count] = unit_radii(int(count))
    total = np.zeros((rows.size, c))
    weight_sum = np.zeros((rows.size, c))
    for i in range(int(n.max(initial=0))):
        on = np.nonzero(n > i)[0]
        r = d_max * radii[n[on], i]  # mm
        angle = phase[on] + 2.0 * math.pi * math.modf(i / GOLDEN_RATIO)[0]
        dy, dx = ppm[on] * r * np.sin(angle), ppm[on] * r * np.cos(angle)
        if options["snap"]:
            y = rows[on] + np.rint(dy).astype(np.int64)
            x = cols[on] + np.rint(dx).astype(np.int64)
            inside = (y >= 0) & (y < h) & (x >= 0) & (x < w)
            y, x = np.clip(y, 0, h - 1), np.clip(x, 0, w - 1)
            read = stack[y, x] * inside[:, None]
            if steps:
                far = ~in_cache(rows[on], cols[on], y, x)
                read[far] = coarse[y[far] >> steps, x[far] >> steps] * inside[far, None]
            z = depth[y, x]
        else:
            read = _bilinear(np.concatenate([stack, depth[..., None]], axis=-1), rows[on] + dy, cols[on] + dx)
            read, z = read[:, :-1], read[:, -1]
        rho = np.sqrt(r * r + (z - z0[on]) ** 2)
        wgt = _weights(rho, r, d, d_max) * read[:, c:c + 1]
        total[on] += wgt * read[:, :c]
        weight_sum[on] += wgt
    blurred = image.copy()
    # A pixel that gathered nothing gives 0, as HDRP's max(totalWeight, FLT_MIN) does.
    blurred[rows, cols] = np.where(weight_sum > 0, total / np.where(weight_sum > 0, weight_sum, 1.0), 0.0)
    return image + mask[..., None] * (blurred - image)
