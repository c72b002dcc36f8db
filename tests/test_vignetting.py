"""The fitted vignetting field: its definition, its derivative, and what it buys a fit.

A model-made face is photographed through a lens whose corners get 20 % less
light. A fit that knows about vignetting must land where the fit of the same
photograph without vignetting lands (same noise draw), and say how strong the
fall-off was; a fit that does not know about it is measurably pulled away.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss import InvalidInputError
from invsss.estimator import FitOptions, build_problem
from invsss.estimator.vignetting import radius_squared, vignetting_at, vignetting_field
from _estimator_scenes import make_pair
from _pair_files import pair_args, write_pair

PROFILE3 = {"weights": [0.3, 0.45, 0.25], "variances": [0.25, 1.2, 5.0]}
TRUTH = invsss.SSSParams(700.0, 300.0, 2.0, PROFILE3["weights"], PROFILE3["variances"])
SIZE = 80
OFFSET = 0.05  # make_pair's black level, which the lens does not shade


def _photographs(seed=4):
    source, _, depth, mask, clean = make_pair("face", TRUTH, size=SIZE, contrast=3.0, seed=seed, noise=0.0)
    noise = 0.01 * float(np.mean(clean[mask > 0])) * np.random.default_rng(seed).standard_normal(clean.shape)
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    c = (SIZE - 1) / 2.0
    rho2 = ((y - c) ** 2 + (x - c) ** 2) / (2 * c**2)  # written out, independent of the module
    shaded = (clean - OFFSET) * (1.0 - 0.2 * rho2)[..., None] + OFFSET
    return source, depth, mask, clean + noise, shaded + noise


@pytest.mark.slow
@jax.enable_x64(True)
def test_field_matches_its_definition():
    rho2 = np.asarray(radius_squared((4, 6), jnp.float64))
    y, x = np.mgrid[0:4, 0:6]
    expected = ((y - 1.5) ** 2 + (x - 2.5) ** 2) / (1.5**2 + 2.5**2)
    np.testing.assert_allclose(rho2, expected, rtol=1e-12)
    field = np.asarray(vignetting_field(jnp.array([-0.3, 0.1], jnp.float64), (4, 6)))
    np.testing.assert_allclose(field, 1.0 - 0.3 * expected + 0.1 * expected**2, rtol=1e-12)
    # Read at the pixel centres, the field at any points is the same field.
    points = np.stack([y.ravel(), x.ravel()], axis=1).astype(float)
    np.testing.assert_allclose(vignetting_at([-0.3, 0.1], points, (4, 6)), field.ravel(), rtol=1e-12)
    between = vignetting_at([-0.3, 0.1], np.array([[0.5, 1.0]]), (4, 6))[0]
    rho2_between = (1.0**2 + 1.5**2) / (1.5**2 + 2.5**2)
    assert between == pytest.approx(1.0 - 0.3 * rho2_between + 0.1 * rho2_between**2, rel=1e-12)


@pytest.mark.slow
def test_projected_residual_derivative_in_the_vignetting_block():
    source, depth, mask, _, photo = _photographs()
    problem = build_problem([(source[:24, :24], photo[:24, :24], depth[:24, :24], mask[:24, :24])],
                            FitOptions(profile=PROFILE3, vignetting=True))
    assert problem.param.free[-1] == "vignetting"
    with jax.enable_x64(True):
        f = jax.jit(lambda u: problem.objective(u)[0])
        z = jnp.asarray(problem.z0).at[-2:].set(jnp.array([-0.15, 0.05]))
        jac = np.asarray(jax.jacfwd(f)(z))
        h = 1e-6
        for k in (z.size - 2, z.size - 1):
            e = jnp.zeros_like(z).at[k].set(h)
            fd = (np.asarray(f(z + e)) - np.asarray(f(z - e))) / (2 * h)
            assert np.linalg.norm(fd) > 0
            assert np.linalg.norm(jac[:, k] - fd) < 1e-6 * np.linalg.norm(fd)


@pytest.fixture(scope="module")
def fits():
    source, depth, mask, plain, shaded = _photographs()
    kw = {"profile": PROFILE3, "n_starts": 2}
    return {
        "reference": invsss.fit_pair(source, plain, depth, mask, **kw),
        "shaded": invsss.fit_pair(source, shaded, depth, mask, **kw),
        "shaded, fitted": invsss.fit_pair(source, shaded, depth, mask, vignetting=True, **kw),
    }


@pytest.mark.slow
def test_fitted_vignetting_recovers_the_unshaded_fit(fits):
    reference, fitted = fits["reference"], fits["shaded, fitted"]
    for name in ("sss_level", "correction", "maxdd"):
        value, ref = float(fitted.values[name]), float(reference.values[name])
        assert abs(value - ref) < reference.stderr[name], name
    record = fitted.vignetting
    a, err = np.asarray(record["coefficients"]), np.asarray(record["stderr"], dtype=float)
    assert np.all(np.abs(a - [-0.2, 0.0]) < 3 * err) and np.all(err < 0.05)
    assert record["corner_gain"] == pytest.approx(0.8, abs=0.02)
    # The same noise is left over (PSNR differs only through the darker peak).
    assert fitted.sigma == pytest.approx(reference.sigma, rel=0.02)
    assert fits["reference"].vignetting is None and fitted.to_dict()["vignetting"] == record
    from invsss.cli.report import _parameter_lines

    shown = [line for line in _parameter_lines(fitted) if line.startswith("vignetting:")]
    assert len(shown) == 1 and f"corner gain {record['corner_gain']:.3f}" in shown[0]
    assert not any(line.startswith("vignetting:") for line in _parameter_lines(fits["reference"]))


@pytest.mark.slow
def test_ignoring_vignetting_biases_the_fit(fits):
    reference, ignored = fits["reference"], fits["shaded"]
    worst = max(abs(float(ignored.values[n]) - float(reference.values[n])) / reference.stderr[n]
                for n in ("sss_level", "correction", "maxdd"))
    assert worst > 10
    assert ignored.sigma > 2 * reference.sigma


def test_vignetting_option_is_checked():
    with pytest.raises(InvalidInputError, match=r"^vignetting: expected true or false, got 'yes'$"):
        FitOptions(vignetting="yes")


@pytest.mark.slow
def test_cli_fit_writes_the_field_into_params_json(tmp_path):
    import json

    import invsss.cli

    source, depth, mask, _, photo = _photographs()
    crop = slice(20, 60)  # a small fit: the flag's path through the CLI, not its accuracy
    files = write_pair(tmp_path, "crop", [image[crop, crop] for image in (source, photo, depth, mask)])
    (tmp_path / "profile.json").write_text(json.dumps(PROFILE3))
    arguments = ["fit", *pair_args(files), "--out", str(tmp_path / "out"), "--starts", "1", "--max-steps", "20",
                 "--vignetting", "--profile", str(tmp_path / "profile.json")]
    assert invsss.cli.main(arguments) == 0
    written = json.loads((tmp_path / "out" / "params.json").read_text())
    assert len(written["vignetting"]["coefficients"]) == 2 and written["vignetting"]["corner_gain"] < 1.0
    params, _ = invsss.read_params(tmp_path / "out" / "params.json")  # still a valid params file
    assert float(params.sss_level) > 0


@pytest.mark.slow
def test_registration_does_not_take_the_fall_off_for_a_zoom():
    # A photograph moved by whole pixels (nothing interpolated), then shaded about
    # its own frame's centre: an aligned fit with vignetting must find the move and
    # no zoom. Registering against an unshaded prediction read the fall-off as a
    # scale of about 0.999, which moves correction by several per cent.
    source, depth, mask, _, _ = _photographs()
    _, _, _, _, clean = make_pair("face", TRUTH, size=SIZE, contrast=3.0, seed=4, noise=0.0)
    moved = np.full_like(clean, OFFSET)
    moved[2:, :-1] = clean[:-2, 1:]  # content 2 rows down and 1 column left
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    c = (SIZE - 1) / 2.0
    rho2 = ((y - c) ** 2 + (x - c) ** 2) / (2 * c**2)
    noise = 0.01 * float(np.mean(clean[mask > 0])) * np.random.default_rng(5).standard_normal(clean.shape)
    photo = (moved - OFFSET) * (1.0 - 0.2 * rho2)[..., None] + OFFSET + noise
    fit = invsss.fit_pair(source, photo, depth, mask, profile=PROFILE3, n_starts=2, align="similarity",
                          vignetting=True)
    warp = fit.alignment[0]
    assert warp["shift_px"] == pytest.approx([2.0, -1.0], abs=0.02)
    assert abs(warp["scale"] - 1.0) < 2e-4 and abs(warp["rotation_deg"]) < 0.02
    assert fit.vignetting["corner_gain"] == pytest.approx(0.8, abs=0.02)
