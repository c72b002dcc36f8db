"""Clipped pixels from the command line (``invsss fit --saturation``): an integer
target's top code is left out by default, a float target is not clipped, a file whose
pixels are all clipped is named, and a bad value is one line."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io import resolved_saturation
from tests.forward._clipped_card import SHAPE
from tests.io._clipped_card import card_on_disk
from tests.io._pair_files import pair_args


def _cli_fit(paths, profile, out, *extra) -> tuple[int, dict, str]:
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        code = main(["fit", *pair_args(paths), "--profile", str(profile), "--fix", "correction=0",
                     "--fix", "maxdd=1", "--starts", "1", *extra, "--out", str(out)])
    content = json.loads((out / "params.json").read_text()) if code == 0 else {}
    return code, content, err.getvalue()


@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_the_cli_names_the_file_whose_pixels_are_all_clipped(tmp_path):
    # A mask given as the target, say: the library says "target", the user typed a path.
    paths, profile = card_on_disk(tmp_path, ".png")
    code, _, err = _cli_fit(paths, profile, tmp_path / "o", "--saturation", "1e-9")
    assert code == 2
    assert err.strip().splitlines()[-1] == (f"invsss: error: {paths['target']} (target): every masked pixel is "
                                            "at or above the saturation level 1e-09")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_the_cli_leaves_out_an_integer_targets_top_code_by_default(tmp_path):
    paths, profile = card_on_disk(tmp_path, ".png")
    count = int(np.sum(invsss.read_image(paths["target"]) >= 1.0))
    assert count > 0.15 * np.prod(SHAPE)
    code, auto, err = _cli_fit(paths, profile, tmp_path / "auto")
    assert code == 0, err
    assert any(f"{count} masked pixel(s) at or above the saturation level 1 " in w for w in auto["warnings"])
    assert abs(auto["sss_level"] / 375.0 - 1.0) < 0.02
    code, kept, err = _cli_fit(paths, profile, tmp_path / "none", "--saturation", "none")
    assert code == 0, err
    assert not any("saturation" in w for w in kept.get("warnings", []))
    assert abs(kept["sss_level"] / 375.0 - 1.0) > 0.1


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_a_float_target_is_not_clipped_by_default(tmp_path):
    paths, profile = card_on_disk(tmp_path, ".exr")
    code, content, err = _cli_fit(paths, profile, tmp_path / "o", "--max-steps", "3")
    assert code == 0, err
    assert not any("saturation" in w for w in content.get("warnings", []))


def test_saturation_auto_sets_no_level_when_a_target_holds_floats(tmp_path):
    paths, _ = card_on_disk(tmp_path, ".png")
    exr = tmp_path / "card_target.exr"
    with pytest.warns(invsss.InputNotice, match=rf"saturation auto: no clipping level set, as a float target \({exr}\)"):
        assert resolved_saturation("auto", [str(paths["target"]), str(exr)]) is None
    assert resolved_saturation("auto", [str(paths["target"])] * 2) == 1.0
    assert resolved_saturation(0.5, [str(exr)]) == 0.5
    assert resolved_saturation(None, [str(paths["target"])]) is None


def test_a_bad_saturation_word_is_a_one_line_error(tmp_path):
    paths, profile = card_on_disk(tmp_path, ".png")
    code, _, err = _cli_fit(paths, profile, tmp_path / "o", "--saturation", "clipped")
    assert code == 2
    assert err.strip().splitlines()[-1] == "invsss: error: --saturation 'clipped': expected auto, none or a number > 0"
