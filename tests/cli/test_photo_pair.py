"""A pair of photographs without a 3D model (issue 33): one distance instead of a depth
map, the parameters a constant depth cannot determine held and reported, and a skin mask
made from the pair when none is given."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.io.photo_pair import HELD_WITH_CONSTANT_DEPTH, MASK_FILE, constant_depth_pair
from tests import ROOT
from tests.forward._face_photographs import PROFILE, SIZE, TRUTH_LEVEL, face_photographs


@pytest.mark.slow
def test_a_constant_depth_pair_measures_sss_level_over_distance():
    """Fitted at its true distance and at twice it, the pair gives sss_level / distance
    within 2 % of the truth's both times: the blur in pixels is what one depth determines."""
    rng = np.random.default_rng(3)
    source, target, disc = face_photographs(rng, 500.0)
    ratios = {}
    for distance in (500.0, 1000.0):
        pair = constant_depth_pair(source, target, distance, disc)
        fit = invsss.fit_pairs([pair], profile=PROFILE, fix=HELD_WITH_CONSTANT_DEPTH, n_starts=1)
        ratios[distance] = float(fit.params.sss_level) / distance
    for distance, ratio in ratios.items():
        assert ratio == pytest.approx(TRUTH_LEVEL / 500.0, rel=0.02), (distance, ratios)


@pytest.fixture(scope="module")
def photo_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("photo_pair")
    source, target, disc = face_photographs(np.random.default_rng(5), 600.0)
    paths = {"visible": folder / "visible.exr", "nir": folder / "nir.exr", "depth": folder / "depth.exr"}
    invsss.write_image(paths["visible"], source.astype(np.float32))
    invsss.write_image(paths["nir"], target.astype(np.float32))
    invsss.write_image(paths["depth"], np.full((SIZE, SIZE), 600.0, np.float32))
    profile = folder / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    return {**paths, "profile": profile, "disc": disc}


def _run(argv):
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.mark.slow
def test_fit_with_a_distance_and_no_mask_writes_the_mask_and_says_what_was_held(photo_files, tmp_path):
    out = tmp_path / "result"
    code, _, err = _run(["fit", "--source", str(photo_files["visible"]), "--target", str(photo_files["nir"]),
                         "--distance", "600", "--profile", str(photo_files["profile"]), "--starts", "1",
                         "--max-steps", "30", "--fix", "maxdd=0.3", "--out", str(out)])
    assert code == 0, err
    content = json.loads((out / "params.json").read_text())
    held = content["inputs"]["held"]
    assert set(held) == {"correction", "maxdd"}
    assert held["correction"]["value"] == HELD_WITH_CONSTANT_DEPTH["correction"]
    assert held["maxdd"]["value"] == 0.3  # a --fix value wins over the default
    assert "constant depth" in held["maxdd"]["why"]
    assert content["fixed"]["correction"] == 0.0 and content["fixed"]["maxdd"] == 0.3
    assert content["inputs"]["pairs"][0]["depth"] == {"kind": "distance", "distance_mm": 600.0}
    assert content["inputs"]["pairs"][0]["mask"]["file"] == MASK_FILE
    mask = invsss.read_mask(out / MASK_FILE) > 0.5
    disc = photo_files["disc"] > 0
    assert (mask & disc).sum() / (mask | disc).sum() > 0.95
    manifest = json.loads((out / "invsss-manifest.json").read_text())
    assert MASK_FILE in json.dumps(manifest)
    assert content["sss_level"] == pytest.approx(TRUTH_LEVEL, rel=0.05)
    # The params file it wrote renders (the held values are numbers).
    params, extras = invsss.read_params(out / "params.json")
    assert float(params.correction) == 0.0 and extras["inputs"]["held"]


@pytest.mark.parametrize("extra, expected", [
    (["--distance", "0"], "--distance: expected the face's distance from the camera in mm, a finite number > 0"),
    (["--distance", "-600"], "a finite number > 0, got -600.0"),
    (["--distance", "nan"], "a finite number > 0, got nan"),
    (["--distance", "600", "--depth", "DEPTH"], "--depth, --distance: give one or the other"),
    ([], "--depth, --distance: give a depth map (--depth FILE, mm) or the face's distance"),
    (["--distance", "600", "--distance", "700"], "--distance: expected one for all pairs or one per pair (1), got 2"),
])
def test_bad_depth_arguments_are_one_line_errors(photo_files, tmp_path, extra, expected):
    extra = [str(photo_files["depth"]) if a == "DEPTH" else a for a in extra]
    out = tmp_path / "o"
    code, _, err = _run(["fit", "--source", str(photo_files["visible"]), "--target", str(photo_files["nir"]),
                         *extra, "--out", str(out)])
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1, err
    assert lines[0].startswith("invsss: error: ") and expected in lines[0]
    assert not out.exists()  # refused before the output directory was made


def test_a_mask_of_another_size_is_refused_naming_it(photo_files, tmp_path):
    small = tmp_path / "small_mask.png"
    invsss.write_image(small, np.ones((SIZE - 2, SIZE), np.float32))
    code, _, err = _run(["fit", "--source", str(photo_files["visible"]), "--target", str(photo_files["nir"]),
                         "--distance", "600", "--mask", str(small), "--out", str(tmp_path / "o")])
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and str(small) in lines[0], err


def _fit_readmes_two_photograph_pair(out, *extra):
    """The README's two-photograph fit into ``out``: ``(params.json's content, stderr)``."""
    folder = ROOT / "data_synthetic" / "twowave_face"
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        code = main(["fit", "--source", f"{folder}/visible/target.exr", "--target", f"{folder}/nir/target.exr",
                     "--distance", "600", *extra, "--out", str(out)])
    assert code == 0, err.getvalue()
    return json.loads((out / "params.json").read_text()), err.getvalue()


@pytest.mark.slow
def test_the_readmes_two_photograph_pair_gives_a_determined_blur_with_the_weights_held(tmp_path):
    # README: with the thesis's 940 nm profile and its weights held, sss_level comes out
    # 82 +- 7 and nothing is undetermined.
    content, _ = _fit_readmes_two_photograph_pair(tmp_path / "o", "--profile", "thesis-nir", "--fix",
                                                  "weights=0.1478,0.1323,0.0004,0.0527,0.09")
    assert content["undetermined"] == []
    level, stderr = content["sss_level"], content["stderr"]["sss_level"]
    assert 0.0 < stderr < 0.15 * level
    assert abs(level - 82.1) < 3.0 * stderr


@pytest.mark.slow
def test_the_readmes_two_photograph_pair_alone_warns_without_promising_a_standard_error(tmp_path):
    # With the five weights free, another blur scale fits within the noise and the data
    # determine no sss_level: the basin warning must not speak of its standard error.
    content, err = _fit_readmes_two_photograph_pair(tmp_path / "o", "--profile", "thesis-nir")
    assert "sss_level" in content["undetermined"] and content["sss_level"] is None
    basin = [w for w in content["warnings"] if "another basin fits as well" in w]
    assert len(basin) == 1 and "standard error" not in basin[0]
    assert "fix weights=" in basin[0] and basin[0] in err


@pytest.mark.slow
def test_the_readmes_two_photograph_pair_measures_one_gaussian_and_says_it_is_under_a_pixel(tmp_path):
    # README: the photo route's default profile is one Gaussian, whose scale the pair
    # determines (issue 47); at 1.65 mm a pixel its width is a third of a pixel, and
    # the fit says that the pixels do not resolve it.
    content, err = _fit_readmes_two_photograph_pair(tmp_path / "o", "--focal-px", "363")
    assert content["profile"] == "single" and content["undetermined"] == []
    assert 0.0 < content["stderr"]["sss_level"] < 0.15 * content["sss_level"]
    blur = content["blur"]
    assert not blur["resolved"] and blur["sigma_px"][0] < 1.0
    assert blur["mm_per_px"] == pytest.approx(600.0 / 363.0)
    assert blur["sigma_mm"][0] == pytest.approx(blur["sigma_px"][0] * 600.0 / 363.0)
    assert "under a pixel" in err
