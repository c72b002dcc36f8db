"""Clipped pixels of a photograph are left out of the fit (``saturation=``).

A pixel at the sensor's top code reads darker than the light that reached it; the
model, which knows no ceiling, bends to match it. Checked on a model-made card
whose target is clipped at a level a fifth of its pixels reach (kept in, they
move sss_level by +38 %; left out, -0.4 %).
"""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.cli import main
from invsss.cli.fit import saturation_level
from _pair_files import pair_args, write_pair

SHAPE = (40, 48)
TRUTH = invsss.SSSParams(375.0, 0.0, 1.0, [0.3, 0.7], [1.0, 4.0])
PROFILE = {"weights": [0.5, 0.5], "variances": [1.0, 4.0]}
FIX = {"correction": 0.0, "maxdd": 1.0}


def _clipped_card():
    rng = np.random.default_rng(2)
    source = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, SHAPE), 1.0) ** 3
    depth, mask = np.full(SHAPE, 500.0), np.ones(SHAPE)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH)) + 0.001 * rng.standard_normal(SHAPE)
    level = float(np.percentile(target, 80))
    return source, np.minimum(target, level), depth, mask, level


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_clipped_pixels_are_left_out_and_counted():
    source, target, depth, mask, level = _clipped_card()
    kept = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1, saturation=level)
    bent = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1)
    error = {name: abs(float(fit.values["sss_level"]) / 375.0 - 1.0) for name, fit in (("kept", kept), ("bent", bent))}
    assert error["kept"] < 0.02
    assert error["bent"] > 3 * error["kept"]
    count = int(np.sum(target >= level))
    assert any(f"{count} masked pixel(s) at or above the saturation level" in w for w in kept.warnings)
    assert not any("saturation" in w for w in bent.warnings)


@pytest.mark.parametrize("level", [0.0, -1.0, float("nan"), "high", True])
def test_a_bad_saturation_level_is_a_one_line_error(level):
    source, target, depth, mask, _ = _clipped_card()
    with pytest.raises(invsss.InvalidInputError, match="^saturation: expected a number > 0 or None"):
        invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, saturation=level)


def test_a_level_below_every_pixel_leaves_nothing_to_fit():
    source, target, depth, mask, _ = _clipped_card()
    with pytest.raises(invsss.InvalidInputError, match="^target: every masked pixel is at or above"):
        invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, saturation=1e-9)


def _card_on_disk(folder, target_ext: str):
    """The clipped card as files, its target exposed so the clipping level is the top code."""
    source, target, depth, mask, level = _clipped_card()
    paths = write_pair(folder, "card", (source, target / level, depth, mask))
    if target_ext != ".exr":
        paths["target"] = folder / f"card_target{target_ext}"
        invsss.write_image(paths["target"], np.asarray(target / level, np.float32), bits=16)
    profile = folder / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    return paths, profile


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
    paths, profile = _card_on_disk(tmp_path, ".png")
    code, _, err = _cli_fit(paths, profile, tmp_path / "o", "--saturation", "1e-9")
    assert code == 2
    assert err.strip().splitlines()[-1] == (f"invsss: error: {paths['target']} (target): every masked pixel is "
                                            "at or above the saturation level 1e-09")
    assert not (tmp_path / "o").exists()


@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_clipping_level_is_the_top_code_of_integer_files_only(tmp_path):
    image = np.full((4, 5), 0.25, np.float32)
    for name, bits in (("a.png", 8), ("b.png", 16), ("c.tif", 8)):
        invsss.write_image(tmp_path / name, image, bits=bits)
        assert invsss.clipping_level(tmp_path / name) == 1.0
        # The level is what the top code decodes to, whatever the decoding.
        invsss.write_image(tmp_path / name, np.ones((4, 5), np.float32), bits=bits)
        assert float(invsss.read_image(tmp_path / name).min()) == invsss.clipping_level(tmp_path / name)
    for name in ("d.exr", "e.tif"):
        invsss.write_image(tmp_path / name, image)
        assert invsss.clipping_level(tmp_path / name) is None
    np.save(tmp_path / "f.npy", image)
    assert invsss.clipping_level(tmp_path / "f.npy") is None
    with pytest.raises(invsss.InvalidInputError, match="g.png: image file not found"):
        invsss.clipping_level(tmp_path / "g.png")


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_the_cli_leaves_out_an_integer_targets_top_code_by_default(tmp_path):
    paths, profile = _card_on_disk(tmp_path, ".png")
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
    paths, profile = _card_on_disk(tmp_path, ".exr")
    code, content, err = _cli_fit(paths, profile, tmp_path / "o", "--max-steps", "3")
    assert code == 0, err
    assert not any("saturation" in w for w in content.get("warnings", []))


def test_saturation_auto_sets_no_level_when_a_target_holds_floats(tmp_path):
    paths, _ = _card_on_disk(tmp_path, ".png")
    exr = tmp_path / "card_target.exr"
    with pytest.warns(invsss.InputNotice, match=rf"saturation auto: no clipping level set, as a float target \({exr}\)"):
        assert saturation_level("auto", [str(paths["target"]), str(exr)]) is None
    assert saturation_level("auto", [str(paths["target"])] * 2) == 1.0
    assert saturation_level("0.5", [str(exr)]) == 0.5
    assert saturation_level("none", [str(paths["target"])]) is None


def test_a_bad_saturation_word_is_a_one_line_error(tmp_path):
    paths, profile = _card_on_disk(tmp_path, ".png")
    code, _, err = _cli_fit(paths, profile, tmp_path / "o", "--saturation", "clipped")
    assert code == 2
    assert err.strip().splitlines()[-1] == "invsss: error: --saturation 'clipped': expected auto, none or a number > 0"


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_a_sweep_with_saturation_auto_leaves_the_top_code_out(tmp_path):
    import invsss.experiments as ex

    paths, _ = _card_on_disk(tmp_path, ".png")
    files = "\n".join(f'{role} = "{paths[role].name}"' for role in ("source", "target", "depth", "mask"))
    experiment = tmp_path / "card.toml"
    experiment.write_text(f"""
task = "fit"
[data]
[[data.files]]
name = "card"
{files}
[base]
profile = {{weights = {PROFILE['weights']}, variances = {PROFILE['variances']}}}
fix = {{correction = 0.0, maxdd = 1.0}}
n_starts = 1
[grid]
saturation = ["auto", 0.5]
""")
    summary = ex.run(experiment, tmp_path / "out", log=None)
    assert (summary.done, summary.failed) == (2, 0)
    rows = ex.results(tmp_path / "out", frame=False)
    top = int(np.sum(invsss.read_image(paths["target"]) >= 1.0))
    half = int(np.sum(invsss.read_image(paths["target"]) >= 0.5))
    by_count = {count: [row for row in rows if any(f"{count} masked pixel(s) at or above the saturation level "
                                                   f"{level} " in w for w in row["warnings"])]
                for count, level in ((top, "1"), (half, "0.5"))}
    assert len(by_count[top]) == 1 and len(by_count[half]) == 1
    assert abs(by_count[top][0]["param.sss_level"] / 375.0 - 1.0) < 0.02
