"""The samples' noise (per-bin standard errors) and the radii a medium fit may trust."""

import numpy as np
import pytest

from invsss.measurement.measure import MeasuredProfile, measure_profile
from invsss.measurement.trusted_radii import trusted_radii
from invsss.validation import InvalidInputError

PX = 0.1
H, W = 60, 120
CENTRE = (30.0, 20.0)


def _images(noise, seed=0):
    rows, cols = np.mgrid[0:H, 0:W].astype(float)
    r = np.hypot(rows - CENTRE[0], cols - CENTRE[1]) * PX
    skin = 0.5 * np.exp(-r / 1.5) / (1.0 + r)
    skin += noise * np.random.default_rng(seed).standard_normal(skin.shape)
    reference = np.zeros((16, 16))
    reference[6:10, 6:10] = 1.0
    return skin, reference


def _measure(noise, seed=0):
    skin, reference = _images(noise, seed)
    return measure_profile(skin, reference, CENTRE, PX, filter_factor=1.0, saturation=None,
                           lit_radius_mm=0.5, band_width_mm=4.0)


def test_stderr_is_the_pixel_noise_over_the_root_of_the_bin_count():
    noise = 2e-3
    m = _measure(noise)
    many = m.num_pixels >= 20
    # level 1 over a 0.16 mm^2 lit area would scale it; the default spot area is 1.
    expected = noise / np.sqrt(m.num_pixels[many])
    ratio = m.reflectance_stderr[many] / expected
    assert 0.85 < np.median(ratio) < 1.15
    # Over seeds the bin means scatter by the reported error.
    means = np.array([_measure(noise, seed).reflectance for seed in range(1, 9)])
    spread = np.std(means, axis=0, ddof=1)[many] / m.reflectance_stderr[many]
    assert 0.8 < np.median(spread) < 1.25


def test_the_profile_slope_across_a_bin_is_not_noise():
    # Noise-free: a bin's pixels differ only by the slope of R over one pixel (a few %
    # of R), which the line fit removes; what is left is curvature, far below 1 %.
    m = _measure(0.0)
    ok = np.isfinite(m.reflectance_stderr)
    assert np.max(m.reflectance_stderr[ok] / m.reflectance[ok]) < 2e-3


def _profile(stderr, pixels=None):
    r = np.arange(1, 81) * PX
    y = np.exp(-r)
    pixels = np.full(r.size, 30) if pixels is None else pixels
    return MeasuredProfile(r, y, pixels, np.asarray(1.0), 0.2, 0.1, CENTRE, stderr)


def test_trusted_radii_stop_at_the_noise_floor_and_keep_the_resolution():
    r = np.arange(1, 81) * PX
    stderr = np.full(r.size, 1e-3)  # R / stderr = 1000 e^-r: below 3 from r = ln 333 = 5.81 mm
    stderr[29] = 1.0  # one bad bin at 3 mm does not end the range
    pixels = np.full(r.size, 30)
    pixels[5] = 2  # too few pixels to know the noise
    t = trusted_radii(_profile(stderr, pixels), PX, min_snr=3.0)
    assert float(t.r_min_mm) == pytest.approx(0.3)  # 3 pixels
    assert float(t.r_max_mm) == pytest.approx(5.8)
    assert not t.mask[5] and t.mask[6]
    assert t.mask[28] and t.mask[30]
    assert "5.90 mm" in t.reasons[2]
    # A stricter floor ends the range sooner.
    assert float(trusted_radii(_profile(stderr), PX, min_snr=30.0).r_max_mm) == pytest.approx(3.5)


def test_trusted_radii_refuse_a_profile_without_errors():
    with pytest.raises(InvalidInputError, match="^measured: has no reflectance_stderr"):
        trusted_radii(_profile(None), PX)
    with pytest.raises(InvalidInputError, match="^min_snr: expected a finite number > 0"):
        trusted_radii(_profile(np.ones(80)), PX, min_snr=0.0)
