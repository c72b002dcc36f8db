"""`invsss fit`, in-process through main(), on a small scene rendered with known parameters."""

from __future__ import annotations

import io
import json
import re
from contextlib import redirect_stderr, redirect_stdout

import jax
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import invsss
from invsss.cli import main
from invsss.cli.progress import ProgressLine
from tests.io._pair_files import pair_args, write_pair

SIZE = 40
# Two Gaussians keep the compiled fit small; the variances are the profile's (the
# default gauge fixes them), so L, c, delta and the weight ratio are recoverable.
PROFILE = {"weights": [0.5, 0.5], "variances": [0.6, 3.0]}
TRUTH = {"sss_level": 800.0, "correction": 250.0, "maxdd": 0.8,
         "weights": [0.35, 0.65], "variances": PROFILE["variances"]}
REQUIRED_KEYS = {"sss_level", "correction", "maxdd", "weights", "variances", "stderr",
                 "undetermined", "loss", "psnr", "ssim", "converged", "iterations"}
FAST = ["--starts", "1", "--max-steps", "12"]


def _scene(rng, gain, offset):
    """Textured source on a bulging, rippled depth (slopes below and above maxdd)."""
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    c = (SIZE - 1) / 2
    r2 = ((x - c) / (0.48 * SIZE)) ** 2 + ((y - c) / (0.48 * SIZE)) ** 2
    depth = 600.0 - 60.0 * np.sqrt(np.clip(1.0 - r2, 0.0, None)) + 4.0 * np.sin(x / 3.0)
    mask = (r2 < 0.8).astype(np.float64)
    fine = gaussian_filter(rng.standard_normal((SIZE, SIZE)), 0.7)
    coarse = gaussian_filter(rng.standard_normal((SIZE, SIZE)), 3.0)
    source = np.clip(0.5 + 0.2 * fine / fine.std() + 0.1 * coarse / coarse.std(), 0.05, None)
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(source, depth, mask, invsss.SSSParams(**TRUTH)))
    target = gain * clean + offset + 0.002 * rng.standard_normal(clean.shape)
    return source, target, depth, mask


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """Two pairs on disk (different texture and exposure) and the profile file."""
    folder = tmp_path_factory.mktemp("fit_scene")
    rng = np.random.default_rng(7)
    pairs = [write_pair(folder, "a", _scene(rng, 0.8, 0.02)),
             write_pair(folder, "b", _scene(rng, 1.1, 0.0))]
    profile = folder / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    return {"pairs": pairs, "profile": profile}


def _is_png(path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; fails for anything that is not a PNG."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR"
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


@pytest.fixture(scope="module")
def single_fit(scene, tmp_path_factory):
    """One fit of pair a with maxdd fixed (at a value other than the truth's)."""
    out = tmp_path_factory.mktemp("fit_single") / "result"  # does not exist yet
    stdout, err = io.StringIO(), io.StringIO()
    with redirect_stderr(err), redirect_stdout(stdout):
        code = main(["fit", *pair_args(scene["pairs"][0]), "--profile", str(scene["profile"]),
                     "--fix", "maxdd=0.7", *FAST, "--out", str(out)])
    return {"code": code, "out": out, "stdout": stdout.getvalue(), "stderr": err.getvalue()}


@pytest.mark.slow
def test_fit_writes_params_prediction_and_report(single_fit, scene):
    assert single_fit["code"] == 0, single_fit["stderr"]
    out = single_fit["out"]
    content = json.loads((out / "params.json").read_text())
    assert REQUIRED_KEYS <= set(content)
    params, extras = invsss.read_params(out / "params.json")
    assert {"stderr", "undetermined", "loss", "psnr", "ssim", "converged", "iterations"} <= set(extras)
    # The fit found the blur: L within 10 % of the truth, a close match on the mask.
    assert abs(float(params.sss_level) - TRUTH["sss_level"]) < 0.1 * TRUTH["sss_level"]
    assert extras["psnr"] > 35.0

    target = invsss.read_image(scene["pairs"][0]["target"])
    fitted = invsss.read_image(out / "fit.exr")
    assert fitted.shape == target.shape
    mask = invsss.read_mask(scene["pairs"][0]["mask"]) > 0
    rms = float(np.sqrt(np.mean((fitted - target)[mask] ** 2)))
    assert rms < 0.01  # noise is 0.002; a wrong fit leaves the blur's structure

    width, height = _is_png(out / "report.png")
    assert width >= 800 and height >= 500


@pytest.mark.slow
def test_fix_holds_the_value_and_reports_it(single_fit):
    content = json.loads((single_fit["out"] / "params.json").read_text())
    _, extras = invsss.read_params(single_fit["out"] / "params.json")
    assert content["maxdd"] == 0.7  # exactly, not re-estimated
    assert extras["fixed"]["maxdd"] == 0.7
    assert extras["stderr"]["maxdd"] is None
    assert set(extras["fixed"]) == {"maxdd", "variances"}  # the gauge fixes the variances


@pytest.mark.slow
def test_fit_prints_summary_and_progress(single_fit):
    summary = single_fit["stdout"].strip().splitlines()
    assert len(summary) == 2 and summary[0].startswith("fit: loss ")
    assert "params.json" in summary[0] and "report.png" in summary[0]
    # Then the blur's width, what the pixels measured (invsss.estimator.blur_width).
    assert summary[1].startswith("fit: blur ") and " px RMS per axis at depth " in summary[1]
    assert re.search(r" at depth [0-9.e+]+ mm$", summary[1]), summary[1]  # the depth with its unit
    # stderr is not a terminal here: plain progress lines, no carriage returns.
    lines = single_fit["stderr"].splitlines()
    assert "\r" not in single_fit["stderr"]
    assert any(line.startswith("fit: iter 1  loss ") for line in lines)
    assert all(line.startswith(("fit: ", "invsss: warning: ")) for line in lines if line)


@pytest.mark.slow
def test_several_pairs_share_one_fit(scene, tmp_path, capsys):
    out = tmp_path / "two"
    code = main(["fit", *pair_args(*scene["pairs"]), "--profile", str(scene["profile"]),
                 "--fix", "maxdd=0.7", *FAST, "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    for k, pair in enumerate(scene["pairs"]):
        fitted = invsss.read_image(out / f"fit_{k}.exr")
        assert fitted.shape == invsss.read_image(pair["target"]).shape
    assert not (out / "fit.exr").exists()
    _, extras = invsss.read_params(out / "params.json")
    # One gain per pair: the second pair was rendered 1.1 / 0.8 times brighter.
    gains = np.asarray(extras["gain"])[:, 0]
    assert gains.shape == (2,)
    np.testing.assert_allclose(gains[1] / gains[0], 1.1 / 0.8, rtol=0.03)
    _is_png(out / "report.png")


def _one_error_line(capsys, code):
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("invsss: error: "), err
    return lines[0]


def test_unknown_fix_name_is_one_line_error(scene, tmp_path, capsys):
    code = main(["fit", *pair_args(scene["pairs"][0]), "--fix", "blur=3", "--out", str(tmp_path / "o")])
    line = _one_error_line(capsys, code)
    assert "'blur'" in line and "sss_level" in line
    assert not (tmp_path / "o").exists()  # nothing is created for a rejected command


@pytest.mark.parametrize("item, expected", [
    ("maxdd", "NAME=VALUE"),
    ("maxdd=0.1,0.2", "single number"),
    ("variances=0.5,x", "comma-separated numbers"),
])
def test_malformed_fix_is_one_line_error(scene, tmp_path, capsys, item, expected):
    code = main(["fit", *pair_args(scene["pairs"][0]), "--fix", item, "--out", str(tmp_path / "o")])
    assert expected in _one_error_line(capsys, code)


def test_mismatched_pair_counts_are_one_line_error(scene, tmp_path, capsys):
    a, b = scene["pairs"]
    args = pair_args(a) + ["--source", str(b["source"]), "--target", str(b["target"])]
    code = main(["fit", *args, "--out", str(tmp_path / "o")])
    line = _one_error_line(capsys, code)
    assert "2 --source, 2 --target, 1 --depth, 1 --mask" in line


def test_out_that_is_a_file_is_refused(scene, tmp_path, capsys):
    existing = tmp_path / "taken"
    existing.write_text("not a directory")
    code = main(["fit", *pair_args(scene["pairs"][0]), "--out", str(existing)])
    assert str(existing) in _one_error_line(capsys, code)
    assert existing.read_text() == "not a directory"


def test_missing_input_file_is_one_line_error(scene, tmp_path, capsys):
    args = pair_args(scene["pairs"][0])
    args[args.index("--target") + 1] = str(tmp_path / "nope.exr")
    code = main(["fit", *args, "--out", str(tmp_path / "o")])
    assert "nope.exr" in _one_error_line(capsys, code)


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_rewrites_one_line_on_a_terminal():
    stream = _Terminal()
    progress = ProgressLine(stream)
    progress(1, 2.5e-3)
    progress.show("fit: a longer line than the first one")
    progress.show("fit: short")
    progress.close()
    text = stream.getvalue()
    assert "\n" not in text
    assert text.startswith("\rfit: iter 1  loss 2.500e-03")
    # Each rewrite pads over the previous, longer line; close() erases it.
    assert "\rfit: short" + " " * (len("fit: a longer line than the first one") - len("fit: short")) in text
    assert text.endswith("\r")


def test_progress_shows_the_stage_when_given():
    stream = io.StringIO()
    ProgressLine(stream)(17, 1.234e-3, "start 2/4")
    assert stream.getvalue() == "fit: start 2/4  iter 17  loss 1.234e-03\n"


@pytest.mark.parametrize("canvas", ["12", "12x", "0x40", "axb"])
def test_malformed_canvas_is_one_line_error(scene, tmp_path, capsys, canvas):
    code = main(["fit", *pair_args(scene["pairs"][0]), "--canvas", canvas, "--out", str(tmp_path / "o")])
    line = _one_error_line(capsys, code)
    assert f"--canvas '{canvas}': expected HxW" in line
    assert not (tmp_path / "o").exists()


def test_a_canvas_smaller_than_the_pair_is_one_line_error(scene, tmp_path, capsys):
    code = main(["fit", *pair_args(scene["pairs"][0]), "--canvas", "8x8", "--out", str(tmp_path / "o")])
    # After the progress line, which the fit had started.
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 2
    assert last == "invsss: error: canvas: the pair is 40 x 40 pixels, larger than the canvas of 8 x 8"


@pytest.mark.parametrize("argv, expected", [
    # argparse named neither: the first was reported at the top level without a hint, the
    # second only as the missing --out.
    (["fit", "--depth-units", "m"], "invsss fit: error: unrecognized option --depth-units (did you mean "
                                    "'--depth-unit'?)"),
    (["fit", "--source", "a.exr", "--output", "x"], "invsss fit: error: unrecognized option --output (did you "
                                                    "mean '--out'?)"),
    (["export", "p.json", "--formats=hdrp"], "invsss export: error: unrecognized option --formats (did you mean "
                                             "'--format'?)"),
])
def test_an_unknown_option_is_named_with_the_closest_known_one(capsys, argv, expected):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith(f"usage: invsss {argv[0]} ") and err[-1] == expected, err


def test_a_unique_prefix_of_an_option_is_still_taken(capsys):
    """argparse takes --overw for --overwrite: the check before it must not refuse it."""
    assert main(["fit", "--overw", "--source", "a.exr"]) == 2  # refused by argparse, for --target and --out
    assert "unrecognized option" not in capsys.readouterr().err


def test_a_value_with_a_space_and_help_beside_a_typo_are_argparses(capsys):
    """A word with a space is a value to argparse whatever it starts with, and --help wins."""
    assert main(["fit", "--source", "a.exr", "--out", "--my results"]) == 2  # for --target, not the value
    assert "unrecognized option" not in capsys.readouterr().err
    assert main(["fit", "--bogus", "--help"]) == 0
    assert "usage: invsss fit" in capsys.readouterr().out
