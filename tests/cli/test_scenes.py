"""``invsss scene``: the pair folder it writes (with a second light's direction for the
fill term), a fitted warp that renders onto the photograph's grid, one-line errors for
a misspelt key, a params file without an alignment and a missing Mitsuba, and Mitsuba
imported only to render."""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.scenes import load_config, parse_config
from tests.scenes._scene_configs import sphere_config

mitsuba = pytest.importorskip("mitsuba", reason='the scene tests need pip install "invsss[scenes]"')



_TOML = """\
spp = 4
seed = 2

[object]
primitive = "sphere"
radius = 40.0

[camera]
position = [0.0, 0.0, 300.0]
look_at = [0.0, 0.0, 0.0]
{camera_extra}
width = 24
height = 24

[[lights]]
type = "point"
position = [150.0, 150.0, 300.0]
intensity = 1e5

[medium]
preset = "thesis-940"
"""


def _write_toml(tmp_path, camera_extra="fov = 20.0"):
    path = tmp_path / "scene.toml"
    path.write_text(_TOML.format(camera_extra=camera_extra))
    return path


def test_scene_command_writes_a_pair_folder(tmp_path, capsys):
    out = tmp_path / "pair"
    assert main(["scene", str(_write_toml(tmp_path)), "--out", str(out), "--width", "16"]) == 0
    files = sorted(os.listdir(out))
    assert files == sorted(["source.exr", "target.exr", "depth.exr", "mask.png", "normal.exr",
                            "coverage.exr", "light.exr", "key.exr", "thickness.exr", "thickness_normal.exr",
                            "key_irradiance.exr", "scene.json", "invsss-manifest.json"])
    info = json.loads((out / "scene.json").read_text())
    assert info["config"]["camera"]["width"] == 16 and info["config"]["camera"]["height"] == 16
    assert info["mitsuba_version"] == mitsuba.__version__ and info["spp"]["target_per_half"] == 2
    assert set(info["noise"]) >= {"psnr_halves_db", "noise_ceiling_db", "noise_rms"}
    source = invsss.read_image(out / "source.exr")
    mask = invsss.read_mask(out / "mask.png")
    assert source.shape == (16, 16, 1) and invsss.read_image(out / "target.exr").shape == (16, 16, 1)
    assert mask.shape == (16, 16) and 0 < mask.sum() < 256
    # A second run into the same folder is refused without --overwrite.
    assert main(["scene", str(_write_toml(tmp_path)), "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_a_scene_with_a_second_light_writes_its_direction_for_the_fill_term(tmp_path):
    from invsss.scenes.path_tracing import light_directions

    text = _TOML.format(camera_extra="fov = 20.0") + """
[[lights]]
type = "directional"
direction = [0.6, 0.0, -0.8]
irradiance = 1.0
"""
    path = tmp_path / "two.toml"
    path.write_text(text)
    out = tmp_path / "pair"
    assert main(["scene", str(path), "--out", str(out), "--width", "16"]) == 0
    fill = invsss.read_image(out / "fill_light.exr")
    light = invsss.read_image(out / "light.exr")
    skin = invsss.read_mask(out / "mask.png") > 0
    # The directional fill: its reversed direction in camera space (the camera looks
    # down -z from +z, so world and camera axes agree), on every skin pixel; the key
    # is a point light, whose direction varies, so the two buffers differ.
    np.testing.assert_allclose(fill[skin], np.broadcast_to([-0.6, 0.0, 0.8], fill[skin].shape), atol=1e-6)
    assert np.abs(light[skin] - fill[skin]).max() > 0.5
    config = parse_config(json.loads((out / "scene.json").read_text())["config"], "scene.json")
    depth = invsss.read_image(out / "depth.exr")[..., 0]
    np.testing.assert_allclose(fill, light_directions(config, depth, light=1), atol=1e-6)


def test_scene_with_a_fitted_warp_renders_onto_the_photographs_grid(tmp_path, capsys):
    from invsss.estimator.registration import Warp

    config = _write_toml(tmp_path)
    plain, moved = tmp_path / "plain", tmp_path / "moved"
    assert main(["scene", str(config), "--out", str(plain), "--source-only"]) == 0
    # A fit's params.json whose registration moved the picture 2 rows down and 3
    # columns left, and turned it by 90 degrees about pixel (13, 11) (the skin
    # mask's centre in a fit): whole pixels, so the moved render is a re-indexed
    # copy wherever a pixel is not on the silhouette.
    warp = Warp("similarity", (2.0, -3.0, float(np.pi / 2), 0.0), (13.0, 11.0))
    params = {"sss_level": 500.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0], "variances": [1.0],
              "alignment": [warp.to_dict()]}
    invsss.write_params(tmp_path / "params.json", params)
    assert main(["scene", str(config), "--out", str(moved), "--source-only",
                 "--warp", str(tmp_path / "params.json")]) == 0
    assert "target.exr" not in os.listdir(moved) and "source.exr" in os.listdir(moved)
    assert json.loads((moved / "scene.json").read_text())["noise"] is None
    before, after = (invsss.read_mask(folder / "mask.png") for folder in (plain, moved))

    def moved_by(mapping):
        rows, cols = np.mgrid[0:24, 0:24]
        to_rows, to_cols = np.rint(mapping(np.stack([rows, cols], -1).reshape(-1, 2))).astype(int).T
        inside = (to_rows >= 0) & (to_rows < 24) & (to_cols >= 0) & (to_cols < 24)
        out = np.zeros_like(before)
        out[to_rows[inside], to_cols[inside]] = before.ravel()[inside]
        return out

    assert before.sum() > 100
    assert (moved_by(warp.map_points) != after).sum() <= 4  # a few silhouette pixels sampled differently
    # The warp taken the wrong way round does not match.
    assert (moved_by(warp.inverse_map_points) != after).sum() > 50


def test_scene_warp_needs_a_params_file_with_one_alignment(tmp_path, capsys):
    invsss.write_params(tmp_path / "params.json", {"sss_level": 500.0, "correction": 0.0, "maxdd": 1.0,
                                                   "weights": [1.0], "variances": [1.0]})
    code = main(["scene", str(_write_toml(tmp_path)), "--out", str(tmp_path / "out"),
                 "--warp", str(tmp_path / "params.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no alignment" in err[0] and "params.json" in err[0]


def test_misspelt_key_is_one_line_naming_it_and_the_nearest_key(tmp_path, capsys):
    path = _write_toml(tmp_path, camera_extra="fvo = 20.0")
    assert main(["scene", str(path), "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "camera.fvo: unknown key" in err and "did you mean 'fov'?" in err
    assert not (tmp_path / "never").exists()
    # Strict numbers: true is not 1.
    bad_light = {"type": "point", "position": [0.0, 0.0, 1.0], "intensity": True}
    with pytest.raises(invsss.InvalidInputError, match=r"^s: lights\[0\]\.intensity: expected a number"):
        parse_config({**sphere_config().model_dump(), "lights": [bad_light]}, "s")
    assert load_config(_write_toml(tmp_path)).camera.fov == 20.0


@pytest.mark.slow
def test_mitsuba_is_imported_only_to_render():
    import subprocess

    code = (
        "import sys, invsss.cli, invsss.scenes\n"
        "invsss.cli.build_parser()\n"
        "invsss.scenes.parse_config({'object': {'primitive': 'sphere', 'radius': 1.0}, 'camera': {'position': "
        "[0.0, 0.0, 9.0], 'look_at': [0.0, 0.0, 0.0], 'fov': 30.0, 'width': 4, 'height': 4}, 'lights': "
        "[{'type': 'point', 'position': [0.0, 0.0, 9.0], 'intensity': 1.0}], 'medium': {'preset': 'thesis-940'}})\n"
        "print([m for m in ('mitsuba', 'drjit', 'trimesh') if m in sys.modules])"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_missing_mitsuba_is_one_line_naming_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # what `import mitsuba` sees when it is not installed
    assert main(["scene", str(_write_toml(tmp_path)), "--out", str(tmp_path / "pair")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and 'pip install "invsss[scenes]"' in err
