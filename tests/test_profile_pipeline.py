"""Measurement pipeline on a dipole-made slab image (issue 7, item 5).

A flat slab of a known medium lit by a small disc spot: each pixel's exitance is the
Jensen dipole summed over the lit pixels, and the white (reflectance 1) Lambertian
reference shows the spot's irradiance. measure_profile -> fit_dipole must give back
the slab's sigma_s' and sigma_a within 10 %, and `invsss profile` must write a
profile that `invsss fit --profile` reads. The path-traced version of this check is
experiments/profile_slab.py (too slow for CI on two cores).
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.measurement.dipole_fit import fit_dipole
from invsss.measurement.measure import measure_profile
from invsss.forward.profiles import jensen_dipole
from invsss.validation import InvalidInputError

PITCH = 0.1  # mm per pixel
SPOT_RADIUS = 0.3  # mm
H, W = 41, 121
CENTRE = (20.0, 15.0)
MEDIA = [(0.7748, 0.02808), (2.4, 0.1)]  # thesis-940, and a denser, darker one


def _spot_images(sigma_s_prime, sigma_a, irradiance=3.0):
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    lit = np.hypot(rows - CENTRE[0], cols - CENTRE[1]) * PITCH <= SPOT_RADIUS
    reference = np.where(lit, irradiance, 0.0)
    skin = np.zeros((H, W))
    with jax.enable_x64(True):
        for y, x in zip(*np.nonzero(lit)):
            r = np.hypot(rows - y, cols - x) * PITCH
            skin += irradiance * PITCH**2 * np.asarray(jensen_dipole(r, sigma_s_prime, sigma_a))
    return skin, reference


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
    measured = _measure(*_spot_images(sigma_s_prime, sigma_a))
    fit = fit_dipole(measured.r_mm, measured.reflectance)
    assert abs(float(fit.sigma_s_prime) / sigma_s_prime - 1) < 0.10
    assert abs(float(fit.sigma_a) / sigma_a - 1) < 0.10
    # And the sum of Gaussians of the same samples describes them.
    gaussians = measured.fit(3)
    assert float(gaussians.rms) < 0.05


@pytest.mark.slow
def test_the_medium_is_told_apart():
    # A fit that ignored the data would pass the test above for one medium only.
    fits = [fit_dipole(*(lambda m: (m.r_mm, m.reflectance))(_measure(*_spot_images(*m))))
            for m in MEDIA]
    assert float(fits[1].sigma_a) > 2.0 * float(fits[0].sigma_a)


def test_fit_dipole_refuses_bad_samples():
    r = np.linspace(1.0, 5.0, 10)
    with pytest.raises(InvalidInputError, match="^reflectance: expected finite values > 0"):
        fit_dipole(r, np.zeros(10))
    with pytest.raises(InvalidInputError, match="^reflectance: expected shape"):
        fit_dipole(r, np.ones(9))


@pytest.mark.slow
def test_cli_profile_feeds_fit(tmp_path, capsys):
    skin, reference = _spot_images(*MEDIA[0])
    invsss.write_image(tmp_path / "skin.exr", skin.astype(np.float32))
    invsss.write_image(tmp_path / "ref.exr", reference.astype(np.float32))
    out = tmp_path / "profile.json"
    code = main(["profile", str(tmp_path / "skin.exr"), str(tmp_path / "ref.exr"),
                 "--mm-per-pixel", str(PITCH), "--filter-factor", "1", "--max-radius-mm", "8",
                 "--lit-radius-mm", "1.5",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    written = json.loads(out.read_text())
    dipole = written["fit"]["dipole"]
    # One channel (read_image gives (H, W, 1)): one value per channel.
    assert abs(dipole["sigma_s_prime"][0] / MEDIA[0][0] - 1) < 0.10
    assert abs(dipole["sigma_a"][0] / MEDIA[0][1] - 1) < 0.10
    profile = invsss.load_profile(out)  # what `invsss fit --profile` reads
    assert profile.num_gaussians == 3
    # The profile's total reflectance is the dipole's (the measurement is absolute).
    total = float(np.sum(profile.total_reflectance()))
    expected = float(invsss.jensen_dipole_total(*MEDIA[0]))
    assert abs(total / expected - 1) < 0.15

    # A second run refuses to overwrite, and a missing file is one line naming it.
    assert main(["profile", str(tmp_path / "nope.exr"), str(tmp_path / "ref.exr"),
                 "--mm-per-pixel", "0.1", "--out", str(tmp_path / "p2.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert "nope.exr" in err and "\n" not in err
