"""``invsss profile`` reads the medium with its uncertainties and says which radii it trusted."""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.measurement.profile_models import PROFILE_MODELS

PITCH = 0.1
SPOT_RADIUS = 0.3
H, W = 41, 121
CENTRE = (20.0, 15.0)
MEDIUM = (0.7748, 0.02808)  # the thesis's 940 nm medium


def _photographs(model, noise, seed=0):
    """A slab lit by a disc spot, each pixel the model's reading summed over the lit
    pixels, with Gaussian noise of ``noise`` times the value plus a small floor; and the
    white reference showing the spot."""
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float64)
    lit = np.hypot(rows - CENTRE[0], cols - CENTRE[1]) * PITCH <= SPOT_RADIUS
    reference = np.where(lit, 2.0, 0.0)
    skin = np.zeros((H, W))
    with jax.enable_x64(True):
        for y, x in zip(*np.nonzero(lit)):
            r = np.maximum(np.hypot(rows - y, cols - x) * PITCH, 0.05)
            skin += 2.0 * PITCH**2 * np.asarray(PROFILE_MODELS[model](r, *MEDIUM, 1.3))
    rng = np.random.default_rng(seed)
    skin = skin + (noise * skin + 2e-4) * rng.standard_normal(skin.shape)
    return skin, reference


@pytest.mark.slow
def test_profile_reports_the_medium_its_errors_and_trusted_radii(tmp_path, capsys):
    skin, reference = _photographs("transport", 0.05)
    invsss.write_image(tmp_path / "skin.exr", skin.astype(np.float32))
    invsss.write_image(tmp_path / "ref.exr", reference.astype(np.float32))
    out = tmp_path / "profile.json"
    code = main(["profile", str(tmp_path / "skin.exr"), str(tmp_path / "ref.exr"), "--mm-per-pixel",
                 str(PITCH), "--filter-factor", "1", "--lit-radius-mm", "1.5", "--out", str(out)])
    captured = capsys.readouterr()
    printed = captured.out
    assert code == 0, captured.err
    medium = json.loads(out.read_text())["fit"]["medium"]
    assert medium["model"] == "transport"
    for key, truth in zip(("sigma_s_prime", "sigma_a"), MEDIUM):
        value, error = medium[key][0], medium[key + "_stderr"][0]
        assert 0 < error < 0.1 * truth
        assert abs(value - truth) < 3 * error + 0.01 * truth
    # The noise floor (2e-4 against a falling profile) ends the trusted range before
    # the image border (10.5 mm), and the report says so.
    assert 1.5 <= medium["r_min_mm"][0] < 1.7
    assert 3.0 < medium["r_max_mm"][0] < 10.0
    assert "trusted radii" in printed and "noise floor" in printed and "+-" in printed
    assert f"sigma_s' {medium['sigma_s_prime'][0]:.4f} +- " in printed


@pytest.mark.slow
def test_profile_with_a_published_model_misreads_a_photograph(tmp_path, capsys):
    # The same photograph read with Burley's exitance profile: its sigma_a is off by
    # far more than the transport model's (the camera reads radiance, not exitance).
    skin, reference = _photographs("transport", 0.0)
    invsss.write_image(tmp_path / "skin.exr", skin.astype(np.float32))
    invsss.write_image(tmp_path / "ref.exr", reference.astype(np.float32))
    errors = {}
    for model in ("transport", "burley"):
        out = tmp_path / f"{model}.json"
        assert main(["profile", str(tmp_path / "skin.exr"), str(tmp_path / "ref.exr"), "--mm-per-pixel",
                     str(PITCH), "--filter-factor", "1", "--lit-radius-mm", "1.5", "--max-radius-mm", "8",
                     "--model", model, "--out", str(out)]) == 0
        medium = json.loads(out.read_text())["fit"]["medium"]
        errors[model] = abs(medium["sigma_a"][0] / MEDIUM[1] - 1)
    capsys.readouterr()
    assert errors["transport"] < 0.02
    assert errors["burley"] > 0.2


def test_profile_refuses_an_eta_without_a_table(tmp_path, capsys):
    skin, reference = _photographs("transport", 0.0)
    invsss.write_image(tmp_path / "skin.exr", skin.astype(np.float32))
    invsss.write_image(tmp_path / "ref.exr", reference.astype(np.float32))
    code = main(["profile", str(tmp_path / "skin.exr"), str(tmp_path / "ref.exr"), "--mm-per-pixel",
                 str(PITCH), "--filter-factor", "1", "--eta", "1.4", "--out", str(tmp_path / "p.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert "eta" in err and "1.3" in err and "\n" not in err


@pytest.mark.slow
def test_profile_writes_engine_values_the_engines_read_as_the_measured_medium(tmp_path, capsys):
    from invsss.io.engine_readings import hdrp_reading, unreal_reading

    skin, reference = _photographs("transport", 0.0)
    invsss.write_image(tmp_path / "skin.exr", skin.astype(np.float32))
    invsss.write_image(tmp_path / "ref.exr", reference.astype(np.float32))
    readers = {"hdrp": hdrp_reading, "unreal": unreal_reading}
    for engine, reader in readers.items():
        out = tmp_path / f"{engine}.json"
        assert main(["profile", str(tmp_path / "skin.exr"), str(tmp_path / "ref.exr"), "--mm-per-pixel",
                     str(PITCH), "--filter-factor", "1", "--lit-radius-mm", "1.5", "--max-radius-mm", "8",
                     "--format", engine, "--out", str(out)]) == 0
        fit = json.loads(out.read_text())["fit"]
        # What the engine renders from the written fields is Burley's d of the measured medium.
        np.testing.assert_allclose(reader(fit["engine"]["fields"]), fit["medium"]["burley_d"][0], rtol=1e-6)
        assert f"{engine}: " in capsys.readouterr().out
    # And that d is the true medium's, through Burley's published fits.
    from invsss.measurement.profile_models import burley_parameters

    with jax.enable_x64(True):
        _, d_true = burley_parameters(*MEDIUM)
    assert abs(fit["medium"]["burley_d"][0] / float(d_true) - 1) < 0.02
