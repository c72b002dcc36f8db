"""The thesis's measurement pipeline on synthetic photographs with a known profile."""

import jax
import numpy as np
import pytest
from scipy.special import erf

from invsss import InvalidInputError, SumOfGaussians, measure_profile
from invsss.measurement.measure import column_average_gain

PX = 0.1  # mm per pixel
H, W = 64, 128
CENTRE = (32.0, 20.0)
HALF_SPOT = 0.15  # the spot is a 0.3 mm square: 3 x 3 pixels
TRUTH_W = np.array([0.2, 0.15, 0.1])
TRUTH_V = np.array([0.15, 0.6, 2.4])  # mm^2
POWER = 9.5  # camera gain times the spot's irradiance
FILTER = 10.0
# A square spot of side s blurs each Gaussian to (nearly) variance v + s^2 / 12.
BLURRED_V = TRUTH_V + (2 * HALF_SPOT) ** 2 / 12


def _square_spot_fraction(t, variance):
    # int over the spot's extent [-h, h] of the 1-D normal density at t - u.
    s = np.sqrt(2.0 * variance)
    return 0.5 * (erf((t + HALF_SPOT) / s) - erf((t - HALF_SPOT) / s))


def _photographs():
    """Skin lit by a square spot (the SoG profile convolved with it, exactly, with erf),
    the directly lit spot overexposed, and the Spectralon through the x10 filter."""
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    y, x = (rows - CENTRE[0]) * PX, (cols - CENTRE[1]) * PX
    skin = POWER * sum(
        w * _square_spot_fraction(x, v) * _square_spot_fraction(y, v) for w, v in zip(TRUTH_W, TRUTH_V)
    )
    spot = (np.abs(x) < HALF_SPOT) & (np.abs(y) < HALF_SPOT)
    skin[spot] = 1.0  # overexposed direct and single scattering
    spectralon = np.zeros((24, 24))
    spectralon[10:13, 10:13] = POWER / FILTER  # 0.95: bright, not saturated
    return skin, spectralon


@pytest.mark.slow
def test_recovers_known_profile_from_synthetic_photographs():
    skin, spectralon = _photographs()
    # A few saturated pixels in the band (dust, a hair's glint) must be left out.
    skin[30, 40] = skin[36, 60] = skin[25, 33] = 1.0
    first = measure_profile(skin, spectralon, CENTRE, PX, filter_factor=FILTER)
    assert first.lit_area_mm2 == pytest.approx(0.09)  # 9 lit pixels of 0.01 mm^2
    m = measure_profile(skin, spectralon, CENTRE, PX, filter_factor=FILTER, spot_area_mm2=first.lit_area_mm2)
    # The default spot area of 1 mm^2 (the thesis's) only scales the profile.
    np.testing.assert_allclose(first.reflectance, m.reflectance * 0.09, rtol=1e-12)
    assert m.r_mm.min() >= m.lit_radius_mm > 0.15  # directly lit area left out
    blurred = np.asarray(SumOfGaussians(TRUTH_W, BLURRED_V)(m.r_mm))
    # What is left is the square spot's blur beyond its variance (kurtosis) and the
    # curvature of R across a one-pixel bin: measured 0.75 %.
    np.testing.assert_allclose(m.reflectance, blurred, rtol=0.015)

    with jax.enable_x64(True):
        fit = m.fit(3)
    # Three Gaussians four times apart are well determined by ~100 clean samples:
    # measured 0.4 % on the variances and 0.2 % on the weights; 2 % still fails for a
    # wrong scale (spot area, filter, Spectralon level) or a missing blur.
    np.testing.assert_allclose(np.asarray(fit.profile.variances), BLURRED_V, rtol=0.02)
    np.testing.assert_allclose(np.asarray(fit.profile.weights), TRUTH_W, rtol=0.02)


def test_thesis_normalisation_with_8bit_counts():
    # Thesis 4.1.2: Spectralon at 244 counts, x10 filter: R = counts / 2440.
    skin = np.full((40, 60), 24.4)
    skin[18:23, 8:13] = 255.0  # the overexposed lit spot
    skin[20, 30] = 255.0  # a stray saturated pixel: left out, not averaged in
    spectralon = np.zeros((20, 20))
    spectralon[8:13, 8:13] = 244.0
    m = measure_profile(skin, spectralon, (20.0, 10.0), 0.2, saturation=255.0)
    np.testing.assert_allclose(m.reflectance, 24.4 / 2440.0, rtol=1e-12)
    assert float(m.spectralon_level) == pytest.approx(244.0)
    # The thesis's column average: a 5 mm band at 0.2 mm per pixel holds 25 rows (the
    # centre row and 12 on each side); the stray pixel's column has one fewer.
    columns = measure_profile(skin, spectralon, (20.0, 10.0), 0.2, saturation=255.0, averaging="column")
    np.testing.assert_allclose(columns.reflectance, 24.4 / 2440.0, rtol=1e-12)
    # Lit radius: farthest lit pixel of the 5 x 5 spot (2.8 px) plus half a diagonal.
    np.testing.assert_allclose(columns.r_mm, 0.2 * np.arange(4, 50))
    expected_counts = np.full(46, 25)
    expected_counts[30 - 14] = 24
    np.testing.assert_array_equal(columns.num_pixels, expected_counts)


def test_column_averaging_reproduces_thesis_band_average():
    skin, spectralon = _photographs()
    m = measure_profile(
        skin, spectralon, CENTRE, PX, filter_factor=FILTER, spot_area_mm2=0.09, averaging="column"
    )
    # Averaging a column of the band averages the 2-D profile over y: each Gaussian
    # keeps its variance, its weight is scaled by the gain. The band's 51 rows span
    # 5.1 mm. Measured agreement 0.4 % (the spot's blur beyond its variance).
    gain = column_average_gain(BLURRED_V, 51 * PX)
    expected = np.asarray(SumOfGaussians(TRUTH_W * gain, BLURRED_V)(m.r_mm))
    np.testing.assert_allclose(m.reflectance, expected, rtol=0.02)
    # Independently: the gain is the mean over the band of a Gaussian's y-factor.
    y = np.linspace(-2.55, 2.55, 20001)
    v = BLURRED_V[0]
    mean_factor = np.trapezoid(np.exp(-(y**2) / (2 * v)), y) / 5.1
    assert gain[0] == pytest.approx(mean_factor, rel=1e-7)
    # ... which is far below R(r) near the spot: the thesis's profile shape is biased.
    ratio = m.reflectance / np.asarray(SumOfGaussians(TRUTH_W, BLURRED_V)(m.r_mm))
    assert ratio[0] < 0.3


def test_direction_auto_centre_and_channels():
    skin, spectralon = _photographs()
    right = measure_profile(skin, spectralon, CENTRE, PX, filter_factor=FILTER)
    mirrored = skin[:, ::-1]
    mirrored_centre = (CENTRE[0], W - 1 - CENTRE[1])
    left = measure_profile(
        mirrored, spectralon, mirrored_centre, PX, filter_factor=FILTER, direction="left"
    )
    np.testing.assert_allclose(left.r_mm, right.r_mm, rtol=1e-12)
    np.testing.assert_allclose(left.reflectance, right.reflectance, rtol=1e-12)
    found = measure_profile(skin, spectralon, None, PX, filter_factor=FILTER)
    assert found.centre == pytest.approx(CENTRE)
    # RGB: each channel normalised by its own Spectralon level.
    tint = np.array([1.0, 0.5, 0.25])
    skin_rgb = np.minimum(skin[..., None] * tint, 1.0)
    spectralon_rgb = spectralon[..., None] * np.ones(3)
    rgb = measure_profile(skin_rgb, spectralon_rgb, CENTRE, PX, filter_factor=FILTER)
    assert rgb.reflectance.shape == (right.r_mm.size, 3)
    np.testing.assert_allclose(rgb.reflectance / tint, right.reflectance[:, None] * np.ones(3), rtol=1e-12)


def test_saturated_spectralon_is_rejected():
    skin, spectralon = _photographs()
    spectralon[11, 11] = 1.0
    with pytest.raises(InvalidInputError, match="spectralon_image: 1 lit pixel"):
        measure_profile(skin, spectralon, CENTRE, PX)


@pytest.mark.parametrize(
    "change, fragment",
    [
        (dict(mm_per_pixel=0.0), "mm_per_pixel: expected a finite number > 0"),
        (dict(centre=(70.0, 5.0)), "centre: (70, 5) lies outside the 64x128 skin_image"),
        (dict(centre="middle"), "centre: expected (row, column) or None"),
        (dict(direction="north"), "direction: expected one of right, left, down, up"),
        (dict(averaging="mean"), "averaging: expected one of radial, column"),
        (dict(band_width_mm=-5.0), "band_width_mm: expected a finite number > 0"),
        (dict(lit_radius_mm=50.0), "skin_image: no usable pixel in the sample band"),
        (dict(spectralon_image=np.zeros((8, 8))), "spectralon_image: has no lit pixel"),
        (dict(spectralon_image=np.ones((8, 8, 3))), "spectralon_image: expected 1 channel(s)"),
        (dict(skin_image=np.ones((64, 128), dtype=np.uint8)), "skin_image: expected linear floating-point"),
        (dict(lit_threshold=1.5), "lit_threshold: expected a fraction in (0, 1)"),
    ],
)
def test_bad_inputs_raise_one_line_errors(change, fragment):
    skin, spectralon = _photographs()
    args = dict(skin_image=skin, spectralon_image=spectralon, centre=CENTRE, mm_per_pixel=PX)
    args.update(change)
    with pytest.raises(InvalidInputError) as info:
        measure_profile(**args)
    assert fragment in str(info.value) and "\n" not in str(info.value)
