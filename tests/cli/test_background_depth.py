"""Renderer-style depth (0 or +inf off the mask) from files: ``invsss render`` accepts
it and names the depth file of a masked hole; a pair loaded from files and fitted is
looked at for a far plane and for whole-millimetre steps once, on the depth as read."""

from __future__ import annotations

import json

import numpy as np
import pytest

import invsss
from invsss.cli import main
from tests.forward._background_scene import PARAMS, H, W, scene, with_background


@pytest.fixture
def files(tmp_path):
    image, depth, mask = scene()
    paths = {k: tmp_path / n for k, n in [("image", "image.exr"), ("mask", "mask.png"),
                                           ("params", "params.json"), ("out", "out.exr")]}
    invsss.write_image(paths["image"], image.astype(np.float32))
    invsss.write_image(paths["mask"], mask.astype(np.float32))
    params = {k: np.asarray(getattr(PARAMS, k)).tolist() for k in
              ("sss_level", "correction", "maxdd", "weights", "variances")}
    paths["params"].write_text(json.dumps(params))
    for name, background in [("finite", None), ("zero", 0.0), ("inf", np.inf)]:
        stored = depth if background is None else with_background(depth, mask, background)
        # .npy: write_image refuses inf, as it should for images.
        paths[name] = tmp_path / f"depth_{name}.npy"
        np.save(paths[name], stored.astype(np.float32))
    holed = depth.copy()
    holed[5, 6] = 0.0
    paths["holed"] = tmp_path / "depth_holed.exr"
    invsss.write_image(paths["holed"], holed.astype(np.float32))
    return paths


def _render_cli(paths, depth_key, out):
    return main(["render", "--image", str(paths["image"]), "--depth", str(paths[depth_key]),
                 "--mask", str(paths["mask"]), "--params", str(paths["params"]),
                 "--out", str(out), "--no-cache"])


def test_cli_render_accepts_renderer_depth(files, tmp_path):
    mask = invsss.read_mask(files["mask"]) > 0
    assert _render_cli(files, "finite", tmp_path / "finite.exr") == 0
    expected = invsss.read_image(tmp_path / "finite.exr")
    for key in ("zero", "inf"):
        assert _render_cli(files, key, tmp_path / f"{key}.exr") == 0
        got = invsss.read_image(tmp_path / f"{key}.exr")
        np.testing.assert_allclose(got[mask], expected[mask], rtol=1e-6)


def test_cli_render_names_the_depth_file_of_a_masked_hole(files, tmp_path, capsys):
    assert _render_cli(files, "holed", tmp_path / "holed_out.exr") == 2
    err = capsys.readouterr().err.strip()
    assert "depth_holed.exr" in err and "1 masked pixel(s)" in err and "\n" not in err


def _notices(folder, image, depth_map, mask_map, about: str, arrays_too: bool = False) -> list[str]:
    """The notices containing ``about`` that a pair loaded from files and fitted
    gives (then the same arrays given to the fit directly, with ``arrays_too``)."""
    import warnings

    import jax

    from invsss.estimator.inputs import prepare_pairs

    invsss.write_image(folder / "s.exr", image.astype(np.float32))
    np.save(folder / "d.npy", depth_map)
    np.save(folder / "m.npy", mask_map)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pair = invsss.load_pair(folder / "s.exr", folder / "s.exr", folder / "d.npy", folder / "m.npy")
        with jax.enable_x64(True):
            prepare_pairs([pair])
            if arrays_too:
                prepare_pairs([(image, image, depth_map, mask_map)])
    return [str(w.message) for w in caught if about in str(w.message)]


def test_a_loaded_pair_is_looked_at_for_background_once_and_on_the_depth_as_read(tmp_path):
    image, depth, mask = scene()
    # 0 off the mask, as renderers write it: once filled, the skin's flat edge is the
    # largest depth and covers most of the frame, which read as a far plane before.
    assert _notices(tmp_path, image, with_background(depth, mask, 0.0), mask, "far plane") == []
    # A far plane the mask reaches into: one notice, naming the file, not a second as "mask".
    leaky = mask.copy()
    leaky[0, 0] = 1.0
    far = np.where(leaky > 0, depth, 1e4)
    far[0, 0] = 1e4
    found = _notices(tmp_path, image, far, leaky, "far plane")
    assert len(found) == 1 and found[0].startswith(str(tmp_path / "m.npy"))


def test_depth_in_whole_millimetres_is_noted_once_and_smooth_depth_is_not(tmp_path):
    image, depth, mask = scene()  # slopes of up to 4 mm a pixel on the bump, 0 on the flat edge
    y, x = np.mgrid[0:H, 0:W]
    smooth = depth + 0.2 * x + 0.15 * y  # and a tilt: no two neighbours at one depth
    assert _notices(tmp_path, image, smooth, mask, "comes in steps of", arrays_too=True) == []
    found = _notices(tmp_path, image, np.round(smooth), mask, "comes in steps of", arrays_too=True)
    # Once for the file, once for the same arrays given directly: not twice for the file.
    assert [m.split(":")[0] for m in found] == [str(tmp_path / "d.npy"), "depth"]
