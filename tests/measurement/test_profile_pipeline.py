"""Measurement pipeline on a dipole-made slab image (issue 7, item 5).

A flat slab of a known medium lit by a small disc spot: each pixel's exitance is the
Jensen dipole summed over the lit pixels, and the white (reflectance 1) Lambertian
reference shows the spot's irradiance. measure_profile -> fit_dipole must give back
the slab's sigma_s' and sigma_a within 10 % (and `invsss profile` must write a
profile that `invsss fit --profile` reads: tests/cli/test_profile_pipeline.py). The path-traced version of this check is
experiments/profile_slab.py (too slow for CI on two cores).
"""

from __future__ import annotations

import numpy as np
import pytest

from invsss.measurement.dipole_fit import fit_dipole
from invsss.measurement.measure import measure_profile
from invsss.validation import InvalidInputError
from tests.forward._spot_slab import MEDIA, PITCH, spot_images


def _measure(skin, reference):
    first = measure_profile(skin, reference, None, PITCH, filter_factor=1.0, saturation=None)
    # From 1.5 mm on: closer in, the spot's own 0.3 mm radius blurs R(r) by a few %
    # and the two coefficients, nearly traded off against each other, move more.
    return measure_profile(skin, reference, None, PITCH, filter_factor=1.0, saturation=None,
                           spot_area_mm2=first.lit_area_mm2, max_radius_mm=8.0,
                           lit_radius_mm=1.5)


@pytest.mark.slow
@pytest.mark.parametrize("sigma_s_prime, sigma_a", MEDIA)
def test_dipole_fit_recovers_the_slab_medium(sigma_s_prime, sigma_a):
    measured = _measure(*spot_images(sigma_s_prime, sigma_a))
    fit = fit_dipole(measured.r_mm, measured.reflectance)
    assert abs(float(fit.sigma_s_prime) / sigma_s_prime - 1) < 0.10
    assert abs(float(fit.sigma_a) / sigma_a - 1) < 0.10
    # And the sum of Gaussians of the same samples describes them.
    gaussians = measured.fit(3)
    assert float(gaussians.rms) < 0.05


@pytest.mark.slow
def test_the_medium_is_told_apart():
    # A fit that ignored the data would pass the test above for one medium only.
    fits = [fit_dipole(*(lambda m: (m.r_mm, m.reflectance))(_measure(*spot_images(*m))))
            for m in MEDIA]
    assert float(fits[1].sigma_a) > 2.0 * float(fits[0].sigma_a)


def test_fit_dipole_refuses_bad_samples():
    r = np.linspace(1.0, 5.0, 10)
    with pytest.raises(InvalidInputError, match="^reflectance: expected finite values > 0"):
        fit_dipole(r, np.zeros(10))
    with pytest.raises(InvalidInputError, match="^reflectance: expected shape"):
        fit_dipole(r, np.ones(9))
