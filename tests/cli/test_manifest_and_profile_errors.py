"""A damaged result manifest and a profile of the wrong channel count from the command
line: ``render`` and a rerun name the damaged manifest, and ``fit`` names the files
whose channels do not match, each in one line."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io.result_dir import MANIFEST_NAME, ResultDir
from invsss.validation import InvalidInputError
from tests.io._damaged_result import damaged_result


@pytest.fixture
def damaged(tmp_path):
    """A committed result whose manifest was then overwritten with text that is not JSON."""
    return damaged_result(tmp_path)


def test_render_and_a_rerun_name_the_damaged_manifest(damaged, tmp_path, capsys):
    for name, image in (("image.exr", np.ones((8, 8, 3))), ("depth.exr", np.full((8, 8), 500.0)),
                        ("mask.png", np.ones((8, 8)))):
        invsss.write_image(tmp_path / name, image.astype(np.float32))
    code = main(["render", "--image", str(tmp_path / "image.exr"), "--depth", str(tmp_path / "depth.exr"),
                 "--mask", str(tmp_path / "mask.png"), "--params", str(damaged / "params.json"),
                 "--out", str(tmp_path / "out.exr")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0
    assert f"manifest {damaged / MANIFEST_NAME} is damaged" in err
    with pytest.raises(InvalidInputError, match="already holds a result whose manifest is damaged"):
        ResultDir(damaged).open()


def test_profile_channel_mismatch_names_the_files(tmp_path, capsys):
    skin, reference = tmp_path / "skin.exr", tmp_path / "ref.exr"
    spot = np.full((32, 32), 0.01, np.float32)
    spot[14:18, 14:18] = 0.5
    invsss.write_image(skin, spot)
    invsss.write_image(reference, np.repeat(spot[..., None], 3, axis=2))
    code = main(["profile", str(skin), str(reference), "--mm-per-pixel", "0.1",
                 "--out", str(tmp_path / "profile.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert err == f"invsss: error: {reference}: expected 1 channel(s) like {skin}, got 3"
    # The same for a reference with no lit pixel.
    invsss.write_image(reference, np.zeros((32, 32), np.float32))
    assert main(["profile", str(skin), str(reference), "--mm-per-pixel", "0.1",
                 "--out", str(tmp_path / "profile.json")]) == 2
    assert capsys.readouterr().err.strip() == (
        f"invsss: error: {reference}: has no lit pixel (nothing above black_level)")
