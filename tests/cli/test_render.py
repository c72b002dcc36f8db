"""`invsss render`: in-process through main(), and once through the real entry point."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import invsss
from invsss.cli import main

H, W = 20, 24

PARAMS = {"sss_level": 600.0, "correction": 300.0, "maxdd": 0.02,
          "weights": [0.4, 0.6], "variances": [0.3, 1.5]}


@pytest.fixture
def scene(tmp_path):
    """A small scene on disk: textured image, sloped depth (mm), 8-bit mask, params."""
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:H, 0:W]
    image = (0.2 + 0.6 * rng.random((H, W, 3))).astype(np.float32)
    depth = (450.0 + 2.0 * x + 0.5 * y).astype(np.float32)
    mask = np.zeros((H, W), np.float32)
    mask[3:17, 4:20] = 1.0
    paths = {k: tmp_path / n for k, n in
             [("image", "image.exr"), ("depth", "depth.exr"), ("mask", "mask.png"),
              ("params", "params.json"), ("out", "out.exr")]}
    invsss.write_image(paths["image"], image)
    invsss.write_image(paths["depth"], depth)
    invsss.write_image(paths["mask"], mask)
    paths["params"].write_text(json.dumps({**PARAMS, "model": "thesis"}))
    return paths


def _args(paths, *extra):
    return ["render", "--image", str(paths["image"]), "--depth", str(paths["depth"]),
            "--mask", str(paths["mask"]), "--params", str(paths["params"]),
            "--out", str(paths["out"]), *extra]


def _expected(paths, model):
    image = invsss.read_image(paths["image"])
    depth = invsss.read_depth(paths["depth"])
    mask = invsss.read_mask(paths["mask"])
    return np.asarray(invsss.render(image, depth, mask, invsss.SSSParams(**PARAMS), model))


def test_render_writes_what_invsss_render_computes(scene, capsys):
    assert main(_args(scene, "--model", "sog")) == 0
    out = invsss.read_image(scene["out"])
    expected = _expected(scene, "sog")
    np.testing.assert_allclose(out, expected, rtol=1e-6, atol=1e-7)
    assert not np.allclose(out, invsss.read_image(scene["image"]), atol=1e-3)  # it did blur
    assert "out.exr" in capsys.readouterr().out


def test_model_comes_from_the_params_file_unless_the_flag_overrides(scene):
    assert main(_args(scene)) == 0  # the file says thesis
    np.testing.assert_allclose(invsss.read_image(scene["out"]), _expected(scene, "thesis"),
                               rtol=1e-6, atol=1e-7)
    assert main(_args(scene, "--model", "sog")) == 0
    np.testing.assert_allclose(invsss.read_image(scene["out"]), _expected(scene, "sog"),
                               rtol=1e-6, atol=1e-7)


def test_depth_scale_is_applied(scene):
    depth_m = invsss.read_depth(scene["depth"]) / 1000.0
    metres = scene["depth"].with_name("depth_m.npy")
    np.save(metres, depth_m)
    args = _args(scene, "--model", "sog")
    args[args.index("--depth") + 1] = str(metres)
    assert main([*args, "--depth-scale", "1000"]) == 0
    np.testing.assert_allclose(invsss.read_image(scene["out"]), _expected(scene, "sog"),
                               rtol=1e-5, atol=1e-6)


def _one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("invsss: error: ")
    assert "Traceback" not in captured.err
    return lines[0]


def test_unknown_params_key_exits_2_with_one_line(scene, capsys):
    scene["params"].write_text(json.dumps({**PARAMS, "variance": [1.0, 2.0]}))
    assert main(_args(scene)) == 2
    line = _one_error_line(capsys)
    assert "params.json" in line and "'variance'" in line
    assert not scene["out"].exists()


def test_bad_inputs_exit_2_naming_the_file(scene, capsys):
    scene["mask"].unlink()
    assert main(_args(scene)) == 2
    assert "mask.png" in _one_error_line(capsys)


def test_bad_output_path_fails_before_rendering(scene, capsys):
    args = _args(scene)
    args[args.index("--out") + 1] = str(scene["out"].with_suffix(".gif"))
    assert main(args) == 2
    assert "out.gif" in _one_error_line(capsys)


def test_per_channel_weights_must_match_the_image(scene, capsys):
    scene["params"].write_text(json.dumps({**PARAMS, "weights": [[0.4, 0.4], [0.6, 0.6]]}))
    assert main(_args(scene)) == 2
    assert "params.json" in _one_error_line(capsys)


@pytest.mark.parametrize("value, shown", [(True, "true"), ("600", '"600"'), (False, "false")])
def test_a_number_given_as_bool_or_string_is_refused(scene, capsys, value, shown):
    scene["params"].write_text(json.dumps({**PARAMS, "sss_level": value}))
    assert main(_args(scene)) == 2
    line = _one_error_line(capsys)
    assert line.endswith(f"params.json: sss_level: expected a number, got {shown}")
    assert not scene["out"].exists()


def _fit_params(weights):
    """A fit's params file: two undetermined weights (null) and the point estimate."""
    return {**PARAMS, "weights": weights, "variances": [0.3, 0.8, 1.5, 3.0],
            "undetermined": ["weights[2]", "weights[3]"],
            "estimate": {**PARAMS, "weights": [0.1, 0.2, 0.3, 0.4], "variances": [0.3, 0.8, 1.5, 3.0]}}


def test_editing_a_determined_weight_of_a_fit_changes_the_rendering(scene, capsys):
    outputs = []
    for first in (0.05, 0.9):
        scene["params"].write_text(json.dumps(_fit_params([first, 0.2, None, None])))
        assert main(_args(scene)) == 0
        assert "weights[2], weights[3] not determined" in capsys.readouterr().err
        outputs.append(invsss.read_image(scene["out"]))
    assert not np.allclose(outputs[0], outputs[1], atol=1e-4)


def test_absurd_sss_level_renders_with_a_warning(scene, capsys):
    scene["params"].write_text(json.dumps({**PARAMS, "sss_level": 1e30}))
    assert main(_args(scene, "--model", "sog")) == 0
    err = capsys.readouterr().err
    assert "invsss: warning:" in err and "sss_level 1e+30" in err and "wider than the 20x24 image" in err


def test_params_of_an_interrupted_fit_are_refused(scene, capsys):
    (scene["params"].parent / "invsss-manifest.json").write_text(json.dumps({"state": "incomplete"}))
    assert main(_args(scene)) == 2
    assert "incomplete result" in _one_error_line(capsys)


def test_linear_codes_flag_reads_8bit_codes_as_linear(scene, capsys):
    png = scene["image"].with_name("image.png")
    invsss.write_image(png, invsss.read_image(scene["image"]))  # 8-bit sRGB-encoded
    args = _args(scene, "--model", "sog")
    args[args.index("--image") + 1] = str(png)
    assert main(args) == 0
    assert "image.png: 8-bit codes decoded as sRGB" in capsys.readouterr().err
    decoded = invsss.read_image(scene["out"])
    assert main([*args, "--linear-codes"]) == 0
    assert "sRGB" not in capsys.readouterr().err
    # sRGB codes read as linear are brighter than their decoded values
    assert float(invsss.read_image(scene["out"]).mean()) > float(decoded.mean()) + 0.05


def test_version_and_missing_command(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"invsss {invsss.__version__}"
    assert main([]) == 2
    assert "command" in capsys.readouterr().err


@pytest.mark.slow
def test_console_script_entry_point(scene):
    # The installed `invsss` script if this interpreter has one, else `python -m invsss`.
    script = Path(sys.executable).with_name("invsss")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "invsss"]
    result = subprocess.run([*command, *_args(scene, "--model", "sog")],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    np.testing.assert_allclose(invsss.read_image(scene["out"]), _expected(scene, "sog"),
                               rtol=1e-6, atol=1e-7)


def test_a_librarys_deprecation_notice_does_not_reach_the_user(scene, capsys, monkeypatch):
    # On a GPU, JAX 0.11 warns while lowering the pass kernels that its Pallas
    # Triton backend is deprecated; the command line printed that on every run
    # under pytest's (and -W default's) filters. Made here from JAX's module
    # on any machine, beside one of invsss's own warnings, which must still show.
    import warnings

    import invsss.cli.render as render_command

    inner = render_command.run

    def run(args, stop):
        warnings.warn_explicit("The Pallas Triton backend is deprecated", DeprecationWarning,
                               "pallas_call.py", 926, module="jax._src.pallas.pallas_call")
        warnings.warn_explicit("a deprecation of invsss's own", DeprecationWarning,
                               "render.py", 1, module="invsss.cli.render")
        return inner(args, stop)

    monkeypatch.setattr(render_command, "run", run)
    warnings.simplefilter("always")  # as pytest's and python -W default's filters show them
    assert main(_args(scene)) == 0
    err = capsys.readouterr().err
    assert "Pallas" not in err
    assert "invsss: warning: a deprecation of invsss's own" in err
