"""The HDRP-like variant of the ``burley`` model (issue 46): it is the model where the
engine's rules are switched off, each rule moves the image the way docs/renderer.md
("What HDRP will show") says, and bad input gets one line."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import invsss
from invsss.forward.burley_screen_space import burley_cdf, render_burley, unit_radii
from invsss.forward.hdrp_screen_space import (
    QUALITY_LEVELS,
    downsampled,
    filter_radius,
    gradient_noise,
    in_cache,
    render_hdrp_like,
    rotation_phases,
    sample_counts,
)
from invsss.validation import InvalidInputError

D = np.array([1.1, 0.55, 0.3])  # mm per channel, red widest


def small_scene(seed=0, h=20, w=24):
    """Random image, rippled depth (mm) and a fractional mask with zeros (as test_burley's)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 500.0 + 6.0 * np.sin(0.4 * xx + 0.2 * yy) + 0.8 * xx
    mask = np.clip(0.5 + 0.9 * np.sin(0.35 * xx + 1.0) * np.cos(0.3 * yy), 0.0, 1.0)
    return rng.uniform(0.05, 1.0, (h, w, 3)), depth, mask


def smooth_field(seed=3, size=40):
    """A grey image with detail over a few pixels, flat depth, all skin."""
    rng = np.random.default_rng(seed)
    image = gaussian_filter(rng.uniform(0.0, 1.0, (size, size)), 1.0)
    return image, np.full((size, size), 500.0), np.ones((size, size))


ENGINE_OFF = {"footprint": False, "snap": False, "rotate": False}


@pytest.fixture(scope="module")
def field():
    """:func:`smooth_field` and its blur with 2000 samples, no engine rules: the reference
    (d = 0.5 mm at 1.6 px per mm, a footprint of 137 samples)."""
    image, depth, mask = smooth_field()
    return image, depth, mask, render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=2000, **ENGINE_OFF)


# ------------------------------------------------------------------ the limit: the burley model


def test_without_the_engine_rules_it_is_the_burley_model_mirrored():
    """32 samples everywhere, bilinear reads, no rotation: the ``burley`` model's blur,
    with the pattern turning the other way (HDRP's golden angle is the mirror of
    the model's), so the image's rows are flipped in and out."""
    image, depth, mask = small_scene(1)
    with jax.enable_x64(True):
        params = invsss.SSSParams(800.0, 0.0, 1.0, np.ones(3), D**2)
        model = np.asarray(render_burley(jnp.asarray(image), jnp.asarray(depth), jnp.asarray(mask), params))
    flip = slice(None, None, -1)
    variant = render_hdrp_like(image[flip], depth[flip], mask[flip], D, 800.0, budget=32, **ENGINE_OFF)[flip]
    np.testing.assert_allclose(variant, model, rtol=0, atol=1e-12)
    unflipped = render_hdrp_like(image, depth, mask, D, 800.0, budget=32, **ENGINE_OFF)
    assert np.abs(unflipped - model).max() > 1e-2  # the turning sense is a real difference


def test_a_constant_stays_and_the_background_is_untouched():
    image, depth, mask = small_scene(2)
    flat = np.full_like(image, 0.7)
    np.testing.assert_allclose(render_hdrp_like(flat, depth, mask, D, 800.0, budget=80), 0.7, rtol=1e-12)
    out = render_hdrp_like(image, depth, mask, D, 800.0, budget=20, frames=2)
    off = mask == 0
    assert off.any()
    np.testing.assert_array_equal(out[off], image[off])


def _round_half_even(v: float) -> int:
    return int(round(v))  # Python's round: halves to even, as HLSL's round


def test_one_pixel_is_what_the_shader_loop_computes():
    """Pixel (9, 11) of a rippled, soft-masked RGB scene, summed sample by sample as
    SubsurfaceScattering.compute's loop does: count from the footprint, radius at
    quantile (i + 1/2) / n, angle 2 pi frac(i / golden ratio) plus the pixel's
    phase, offset rounded, weight of Burley's profile at the 3D distance over the
    pdf of the widest channel, times the mask where the sample lands."""
    image, depth, mask = small_scene(9, h=24, w=28)
    y0, x0, level = 9, 11, 150.0
    out = render_hdrp_like(image, depth, mask, D, level, budget=40, seed=77)
    ppm, d_max = level / depth[y0, x0], D.max()
    n = min(math.floor(math.pi * (filter_radius(d_max) * ppm) ** 2 / 4), 40)
    assert 10 < n < 40
    phase = rotation_phases(24, 28, 77)[y0, x0]
    total, weights = np.zeros(3), np.zeros(3)
    for i in range(n):
        r = d_max * unit_radii(n)[i]
        angle = phase + 2 * math.pi * ((i / ((1 + math.sqrt(5)) / 2)) % 1.0)
        y = y0 + _round_half_even(ppm * r * math.sin(angle))
        x = x0 + _round_half_even(ppm * r * math.cos(angle))
        if not (0 <= y < 24 and 0 <= x < 28):
            continue
        rho = math.hypot(r, depth[y, x] - depth[y0, x0])
        profile = (np.exp(-rho / D) + np.exp(-rho / (3 * D))) / (8 * math.pi * D)  # R(rho) rho
        pdf = (math.exp(-r / d_max) + math.exp(-r / (3 * d_max))) / (4 * d_max)
        w = profile / pdf * mask[y, x]
        total += w * image[y, x]
        weights += w
    expected = image[y0, x0] + mask[y0, x0] * (total / weights - image[y0, x0])
    np.testing.assert_allclose(out[y0, x0], expected, rtol=1e-12)


def test_a_pixel_that_gathers_nothing_goes_black():
    """One skin pixel alone, one sample that lands off it: HDRP divides 0 by its
    smallest weight and writes 0 (the burley model would keep the pixel's value)."""
    image, depth = np.full((21, 21), 0.6), np.full((21, 21), 500.0)
    mask = np.zeros((21, 21))
    mask[10, 10] = 1.0
    out = render_hdrp_like(image, depth, mask, 2.0, 800.0, budget=1)
    assert out[10, 10] == 0.0
    np.testing.assert_array_equal(np.delete(out.ravel(), 10 * 21 + 10), 0.6)


# ------------------------------------------------------------------ rule 1: footprint and budget


def test_the_filter_radius_holds_997_per_mille_of_the_profile():
    lo, hi = 0.0, 100.0
    for _ in range(200):  # bisection on the CDF: an inverse independent of the closed form
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if burley_cdf(mid) < 0.997 else (lo, mid)
    assert filter_radius(1.0) == pytest.approx(0.5 * (lo + hi), rel=1e-12)
    assert filter_radius(0.7) == pytest.approx(0.7 * filter_radius(1.0), rel=1e-12)


def test_the_sample_count_is_a_quarter_of_the_footprint_capped_by_the_budget():
    # d = 1 mm, 1 px per mm: radius 16.56 px, pi r^2 / 4 = 215.5 samples wanted.
    depth = np.array([[400.0, 800.0, 4000.0, 8000.0, 24000.0]])
    wanted = [math.floor(math.pi * (filter_radius(1.0) * 400.0 / z) ** 2 / 4) for z in depth[0]]
    assert wanted == [215, 53, 2, 0, 0]
    assert sample_counts(depth, 1.0, 400.0, 1000).tolist() == [wanted]
    assert sample_counts(depth, 1.0, 400.0, 40).tolist() == [[40, 40, 2, 0, 0]]
    assert sample_counts(depth, 1.0, 400.0, 40, footprint=False).tolist() == [[40] * 5]
    assert QUALITY_LEVELS == {"low": (20, 0), "medium": (40, 0), "high": (80, 0), "max": (1000, 2)}


def test_a_footprint_under_one_sample_is_not_blurred():
    """Far pixels (count 0: a filter radius of 1.1 px) keep their value exactly; near
    ones are blurred; the model's rule (footprint off) blurs both."""
    rng = np.random.default_rng(4)
    image = rng.uniform(0.1, 1.0, (16, 16))
    depth = np.where(np.arange(16)[None, :] < 8, 500.0, 6000.0) * np.ones((16, 1))
    mask = np.ones((16, 16))
    counts = sample_counts(depth, 0.5, 800.0, 40)
    assert counts[0, 0] > 0 and counts[0, -1] == 0
    far = counts == 0
    out = render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=40)
    np.testing.assert_array_equal(out[far], image[far])
    assert np.abs(out[~far] - image[~far]).max() > 1e-2
    everywhere = render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=40, footprint=False)
    assert np.abs(everywhere[far] - image[far]).max() > 1e-4


def test_zero_distance_leaves_the_image():
    image, depth, mask = small_scene(5)
    np.testing.assert_array_equal(render_hdrp_like(image, depth, mask, 0.0, 800.0), image)


def test_a_larger_budget_comes_closer_to_the_full_integral(field):
    """Where the footprint asks for 137 samples, 20 < 40 < 80 < 1000 budgets come
    monotonically closer to a 2000-sample reference (interior pixels)."""
    image, depth, mask, reference = field
    assert sample_counts(depth, 0.5, 800.0, 1000)[0, 0] == 137
    inner = (slice(12, -12), slice(12, -12))
    errors = [np.sqrt(np.mean((render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=b, snap=False,
                                                rotate=False) - reference)[inner] ** 2))
              for b in (20, 40, 80, 1000)]
    assert errors == sorted(errors, reverse=True) and errors[0] > 3 * errors[-1], errors


# ------------------------------------------------------------------ rule 4: whole pixels


def test_samples_under_half_a_pixel_read_the_pixel_itself():
    """A footprint of one sample (0.15 px out): rounded, it reads the centre, so the
    image is unchanged; read bilinearly it moves."""
    image = np.linspace(0.0, 1.0, 16)[None, :] * np.ones((16, 1))
    depth, mask = np.full((16, 16), 500.0), np.ones((16, 16))
    d = 0.08 * 500.0 / 800.0  # d p = 0.08 px
    assert (sample_counts(depth, d, 800.0, 40) == 1).all()
    np.testing.assert_array_equal(render_hdrp_like(image, depth, mask, d, 800.0, rotate=False), image)
    bilinear = render_hdrp_like(image, depth, mask, d, 800.0, rotate=False, snap=False)
    assert np.abs(bilinear - image)[2:-2, 2:-2].max() > 1e-3


def test_samples_beyond_the_border_are_dropped_not_clamped():
    """A bright last column: clamp-to-edge reads it again for every sample beyond the
    border, HDRP's loads there read nothing, so the border pixels keep less of it."""
    image = np.zeros((24, 24))
    image[:, -1] = 1.0
    depth, mask = np.full((24, 24), 500.0), np.ones((24, 24))
    snapped = render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=32, footprint=False, rotate=False)
    clamped = render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=32, **ENGINE_OFF)
    rows = slice(6, -6)
    assert clamped[rows, -1].min() > 0.5
    assert (snapped[rows, -1] < clamped[rows, -1] - 0.1).all()


# ------------------------------------------------------------------ rule 3: rotation


def _one_at_a_time(x: int) -> int:
    """Jenkins' one-at-a-time round on Python integers, written out again for the test."""
    m = 0xFFFFFFFF
    x = (x + (x << 10)) & m
    x ^= x >> 6
    x = (x + (x << 3)) & m
    x ^= x >> 11
    return (x + (x << 15)) & m


def test_the_phase_is_hdrps_hash_of_the_pixel_and_the_key():
    phases = rotation_phases(5, 7, 12345)
    for y, x in [(0, 0), (4, 6), (2, 3)]:
        hashed = _one_at_a_time(x ^ _one_at_a_time(y ^ _one_at_a_time(12345)))
        assert phases[y, x] == 2.0 * math.pi * (hashed & 0x7FFFFF) / 2.0**23
    big = rotation_phases(64, 64, 0)
    assert abs(np.mean(np.cos(big))) < 0.05 and abs(np.mean(np.sin(big))) < 0.05
    assert np.all((big >= 0) & (big < 2 * math.pi))
    assert not np.array_equal(big, rotation_phases(64, 64, 1))


def test_rotation_turns_the_pattern_into_noise_that_frames_average_away(field):
    image, depth, mask, reference = field
    inner = (slice(12, -12), slice(12, -12))

    def error(**options):
        out = render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=20, snap=False, **options)
        return np.sqrt(np.mean((out - reference)[inner] ** 2))

    one, many = error(), error(frames=32)
    assert not np.array_equal(render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=20, seed=1),
                              render_hdrp_like(image, depth, mask, 0.5, 800.0, budget=20, seed=2))
    assert many < 0.5 * one, (one, many)
    assert many < 0.5 * error(rotate=False)


# ------------------------------------------------------------------ rule 6: downsampling


def test_max_quality_reads_one_pixel_of_each_block():
    rows, cols = np.mgrid[0:50, 0:50].astype(np.float64)
    noise = gradient_noise(rows, cols, 3)
    x, y = cols + 3 * 2.083, rows + 3 * 4.867  # Jimenez's constants, typed again
    np.testing.assert_allclose(noise, np.mod(52.9829189 * np.mod(0.06711056 * x + 0.00583715 * y, 1.0), 1.0))
    assert np.all((noise >= 0) & (noise < 1)) and noise.std() > 0.2
    stack = np.arange(10 * 9 * 2, dtype=np.float64).reshape(10, 9, 2) + 1.0
    picked = downsampled(stack, 2, 5)
    assert picked.shape == (3, 3, 2)
    for r in range(3):
        for c in range(3):
            index = int(gradient_noise(np.float64(r), np.float64(c), 5) * 16)
            y, x = 4 * r + index % 4, 4 * c + index // 4  # index // 4 moves along x
            expected = stack[y, x] if (y < 10 and x < 9) else np.zeros(2)
            np.testing.assert_array_equal(picked[r, c], expected)
    depth, mask = np.full((24, 24), 500.0), np.ones((24, 24))
    blocks = np.kron(np.random.default_rng(6).uniform(0.1, 1.0, (6, 6)), np.ones((4, 4)))
    full = render_hdrp_like(blocks, depth, mask, 0.5, 800.0, budget=80, rotate=False)
    coarse = render_hdrp_like(blocks, depth, mask, 0.5, 800.0, budget=80, rotate=False, downsample_steps=2)
    np.testing.assert_allclose(coarse, full, rtol=1e-12)  # constant blocks: any pick is the same
    fine = np.random.default_rng(7).uniform(0.1, 1.0, (24, 24))
    assert not np.allclose(render_hdrp_like(fine, depth, mask, 0.5, 800.0, budget=80, rotate=False,
                                            downsample_steps=2),
                           render_hdrp_like(fine, depth, mask, 0.5, 800.0, budget=80, rotate=False))


def test_samples_in_the_tiles_cache_read_full_resolution():
    """The cache of pixel (17, 17)'s tile spans rows and columns 14 to 33; a blur whose
    samples all stay within 2 px reads only the cache, so downsampling changes nothing."""
    inside = in_cache(np.array([17, 17, 17, 17, 0]), np.array([17, 17, 17, 17, 15]),
                       np.array([14, 13, 33, 17, -2]), np.array([33, 17, 17, 34, 17]))
    assert inside.tolist() == [True, False, True, False, True]
    fine = np.random.default_rng(8).uniform(0.1, 1.0, (40, 40))
    depth, mask = np.full((40, 40), 500.0), np.ones((40, 40))
    d = 0.12  # the widest of 40 samples reaches 2.4 px, rounded to at most 2 per axis
    full = render_hdrp_like(fine, depth, mask, d, 800.0, budget=40, footprint=False)
    assert np.abs(full - fine).max() > 1e-2
    coarse = render_hdrp_like(fine, depth, mask, d, 800.0, budget=40, footprint=False, downsample_steps=2)
    np.testing.assert_array_equal(coarse, full)


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize("change, message", [
    ({"d_mm": [0.5, 0.5]}, r"^d_mm: expected one distance or one per image channel \(3\), got 2 values$"),
    ({"d_mm": [0.5, -1.0, 0.2]}, r"^d_mm: expected finite distances >= 0 in mm, got \[0.5, -1.0, 0.2\]$"),
    ({"d_mm": float("nan")}, r"^d_mm: expected finite distances >= 0 in mm"),
    ({"d_mm": "0.5"}, r"^render_hdrp_like: d_mm: expected a number"),
    ({"sss_level": 0.0}, r"^sss_level: expected one finite number > 0"),
    ({"sss_level": [800.0, 900.0]}, r"^sss_level: expected one finite number > 0"),
    ({"budget": 0}, r"^budget: expected an integer >= 1 \(HDRP's quality levels: 20, 40, 80, 1000\), got 0$"),
    ({"budget": 2.5}, r"^budget: expected an integer >= 1"),
    ({"budget": True}, r"^budget: expected an integer >= 1"),
    ({"frames": 0}, r"^frames: expected an integer >= 1, got 0$"),
    ({"seed": -1}, r"^seed: expected an integer >= 0, got -1$"),
    ({"downsample_steps": -1}, r"^downsample_steps: expected an integer >= 0"),
    ({"snap": "yes"}, r"^snap: expected True or False, got 'yes'$"),
    ({"downsample_steps": 2, "snap": False}, r"^downsample_steps: HDRP reads the downsampled image at whole pixels"),
    ({"image": np.zeros((20, 24, 2))}, r"^image: expected 1 or 3 channels"),
    ({"mask": np.full((20, 24), 2.0)}, r"^mask: expected values in \[0, 1\]"),
    ({"depth": np.zeros((20, 24))}, r"^depth: expected finite depth > 0 wherever the mask is 1"),
])
def test_bad_input_gets_one_line(change, message):
    image, depth, mask = small_scene(8)
    inputs = {"image": image, "depth": depth, "mask": mask, "d_mm": D, "sss_level": 800.0}
    change = dict(change)
    options = {k: change.pop(k) for k in list(change) if k not in inputs}
    inputs.update(change)
    with pytest.raises(InvalidInputError, match=message) as caught:
        render_hdrp_like(inputs["image"], inputs["depth"], inputs["mask"], inputs["d_mm"], inputs["sss_level"],
                         **options)
    assert "\n" not in str(caught.value)
