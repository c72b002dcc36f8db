"""One-line errors that name the file (issue 30, case 8): a result whose manifest is
garbled is damaged, not interrupted; `invsss profile` names the images it was given."""

from __future__ import annotations

import json

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io.result_dir import MANIFEST_NAME, ResultDir, result_state
from invsss.validation import InvalidInputError

PARAMS = {"sss_level": 600.0, "correction": 300.0, "maxdd": 0.02,
          "weights": [0.4, 0.6], "variances": [0.3, 1.5]}


@pytest.fixture
def damaged(tmp_path):
    """A committed result whose manifest was then overwritten with text that is not JSON."""
    out = tmp_path / "result"
    with ResultDir(out) as directory:
        directory.commit({"params.json": lambda path: open(path, "w").write(json.dumps(PARAMS))})
    assert invsss.read_params(out / "params.json")  # whole, it reads
    (out / MANIFEST_NAME).write_text('{"state": "compl')
    return out


def test_a_garbled_manifest_is_damaged_not_interrupted(damaged):
    assert result_state(damaged) == "damaged"
    with pytest.raises(InvalidInputError) as caught:
        invsss.read_params(damaged / "params.json")
    message = str(caught.value)
    assert message == (f"{damaged / 'params.json'}: its result's manifest {damaged / MANIFEST_NAME} is "
                       "damaged (not a JSON object), so whether the result is whole is unknown; re-run it")
    assert "interrupted" not in message and "incomplete" not in message


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
