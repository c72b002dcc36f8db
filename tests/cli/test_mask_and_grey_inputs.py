"""Masks stored with codes 0 and 1 and grey photographs stored as three identical
channels from the command line: ``invsss render`` and ``invsss fit`` give the results
of the plain files (issue 30, cases 1 and 2), and the law's key buffer follows a grey
source, as a sweep's trial reads it too."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import invsss
from invsss.cli import main
from tests.io._mask_and_grey import FRAN, H, W, grey_files, grey_image, notices, pair_files, rgb_source, write_codes
from tests.io._mask_and_grey import scene  # noqa: F401 (fixture)


def test_render_with_a_0_1_mask_blurs_as_with_the_full_mask(scene, tmp_path, capsys):
    outputs = {}
    for mask in ("mask", "mask01"):
        outputs[mask] = tmp_path / f"out_{mask}.exr"
        assert main(["render", "--image", str(scene["image"]), "--depth", str(scene["depth"]),
                     "--mask", str(scene[mask]), "--params", str(scene["params"]),
                     "--out", str(outputs[mask])]) == 0
        err = capsys.readouterr().err
    np.testing.assert_array_equal(invsss.read_image(outputs["mask01"]), invsss.read_image(outputs["mask"]))
    assert f"invsss: warning: {scene['mask01']}: mask codes are 0 and 1" in err
    assert err.count("\n") == 1


@pytest.mark.slow
@pytest.mark.parametrize("case", ["mask01", "grey_rgb"])
def test_fit_of_fran_front_with_a_0_1_mask_or_a_grey_rgb_target_is_the_reference(tmp_path, capsys, case):
    """The issue's numbers: sss_level 4082.7 (0/1 mask) and 1081.7 (grey as RGB) instead of 598.1."""
    files = {role: os.path.join(FRAN, f"{role}.{'png' if role == 'mask' else 'exr'}")
             for role in ("source", "target", "depth", "mask")}
    if case == "mask01":
        files["mask"] = write_codes(tmp_path / "mask01.png",
                                     (invsss.read_mask(files["mask"]) > 0.5).astype(np.uint8), "uint8")
    else:
        target = invsss.read_image(files["target"])
        files["target"] = str(tmp_path / "target_rgb.exr")
        invsss.write_image(files["target"], np.repeat(target, 3, axis=2))
    out = tmp_path / "fit"
    args = [a for role, path in files.items() for a in (f"--{role}", path)]
    assert main(["fit", *args, "--out", str(out), "--no-cache"]) == 0
    err = capsys.readouterr().err
    assert ("mask codes are 0 and 1" if case == "mask01" else "its three channels are identical") in err
    fitted = json.loads((out / "params.json").read_text())
    assert fitted["sss_level"] == pytest.approx(598.1, abs=0.1)


def test_the_key_light_image_follows_a_grey_source_stored_as_rgb(tmp_path):
    """The law's key buffer must have the source's channels: one, when load_pair read a
    grey source stored as RGB as one channel (before a grey target)."""
    from invsss.cli.arguments import read_key_buffer
    from invsss.sweeps.runner import load_trial_pairs
    from invsss.sweeps.trials import Trial

    grey_source, key = tmp_path / "source.exr", tmp_path / "key.exr"
    invsss.write_image(grey_source, np.repeat(grey_image(7)[..., None], 3, 2))
    invsss.write_image(key, np.repeat(0.5 * grey_image(7)[..., None], 3, 2))
    one, _ = grey_files(tmp_path, ".exr")
    files = pair_files(tmp_path, grey_source, one)
    pair, _ = notices(lambda: invsss.load_pair(*files))
    assert pair.source.shape == (H, W, 1)
    read, notes = notices(lambda: read_key_buffer(key, pair.source, False))
    np.testing.assert_array_equal(read[..., 0], 0.5 * grey_image(7))
    assert notes == [f"{key}: its three channels are identical (a grey image stored as RGB); read as one grey channel"]
    # A sweep's trial reads it the same way.
    roles = dict(zip(("source", "target", "depth", "mask"), files), key=key)
    trial = Trial("t", 0, "fit", {"light_terms": "law"}, ({"name": "p", **{k: os.path.basename(v) for k, v in roles.items()}},),
                  {}, str(tmp_path))
    (loaded,), _ = notices(lambda: load_trial_pairs(trial))
    assert loaded.source.shape == loaded.key.shape == (H, W, 1)
    # A colour image stays as it is, asked or not.
    colour = rgb_source(tmp_path)
    assert invsss.read_image(colour, grey=True).shape == (H, W, 3)
