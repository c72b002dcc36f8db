"""The ``burley`` model from the command line: ``invsss fit --model burley`` recovers
every channel's d, and ``invsss export`` writes the engines' profiles."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import jax
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import invsss
from invsss.cli import main
from invsss.io.engine_profiles import hdrp_distances, unreal_distances
from tests.forward._burley_scenes import D, burley_params
from tests.io._pair_files import pair_args, write_pair


def model_made_pair(size, seed):
    """A textured source on a tilted, curved face-sized surface (mm), blurred by ``D``."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    fine = gaussian_filter(rng.standard_normal((size, size, 3)), (0.8, 0.8, 0))
    coarse = gaussian_filter(rng.standard_normal((size, size, 3)), (4.0, 4.0, 0))
    source = np.clip(0.5 + 0.2 * fine / fine.std() + 0.1 * coarse / coarse.std(), 0.05, None)
    depth = 480.0 + 0.6 * xx + 0.3 * yy + 0.004 * (xx - size / 2) ** 2
    mask = np.ones((size, size))
    mask[:, :4] = 0.0
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(source, depth, mask, burley_params(), model="burley"))
    target = 0.9 * clean + 0.02 + 0.002 * rng.standard_normal(clean.shape)
    return source, target, depth, mask


@pytest.mark.slow
@pytest.mark.parametrize("size", [64, 96])
def test_cli_fit_recovers_the_distances(size, tmp_path):
    # No option but the model: its default gauge ("depth") must measure every channel's d,
    # not hold the start (0.759 mm on each channel before issue 46).
    pair = write_pair(tmp_path, "pair", model_made_pair(size, seed=size))
    out = tmp_path / "fit"
    with redirect_stderr(io.StringIO()), redirect_stdout(io.StringIO()):
        code = main(["fit", *pair_args(pair), "--model", "burley", "--out", str(out)])
    assert code == 0
    result = json.loads((out / "params.json").read_text())
    assert result["gauge"] == "depth" and "variances" not in result["fixed"]
    d = np.sqrt(result["variances"])
    np.testing.assert_allclose(d, D, rtol=0.02)
    assert result["sss_level"] == pytest.approx(800.0, rel=0.02)
    stderr = np.asarray(result["stderr"]["variances"])
    assert stderr.shape == (3,) and np.all(stderr > 0)


def test_cli_export_writes_the_engine_assets(tmp_path, capsys):
    path = tmp_path / "params.json"
    invsss.write_params(path, {"sss_level": 800.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0, 1.0, 1.0],
                               "variances": (D**2).tolist(), "model": "burley"})
    assert main(["export", str(path), "--format", "hdrp"]) == 0
    hdrp = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(hdrp_distances(hdrp["fields"]), D, rtol=1e-12)
    assert main(["export", str(path), "--format", "unreal", "--albedo", "0.9/0.5/0.4",
                 "--out", str(tmp_path / "unreal.json")]) == 0
    unreal = json.loads((tmp_path / "unreal.json").read_text())
    np.testing.assert_allclose(unreal_distances(unreal["fields"]), D, rtol=1e-12)
    capsys.readouterr()
    sog = tmp_path / "sog.json"
    invsss.write_params(sog, {"sss_level": 800.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0],
                              "variances": [1.0], "model": "sog"})
    assert main(["export", str(sog), "--format", "hdrp"]) == 2
    assert "hdrp takes a burley fit" in capsys.readouterr().err
