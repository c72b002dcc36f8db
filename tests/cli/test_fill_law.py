"""The ``fill`` light term from the command line: ``invsss fit``, ``render`` and
``export`` with the fill light's buffer."""

from __future__ import annotations

import json

import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms
from tests.forward._lit_scenes import PROFILE, dome_with_two_lights, lit_target

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
def test_cli_fit_render_and_export_with_the_fill_light_buffer(tmp_path, capsys):
    from invsss.cli import main
    from tests.io._pair_files import pair_args, write_pair

    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7], fill=1.0), noise=0.0)
    paths = write_pair(tmp_path, "lit", (source, target, depth, mask))
    files = {}
    for name in ("normal", "light", "key", "fill_light"):
        files[name] = str(tmp_path / f"{name}.exr")
        invsss.write_image(files[name], np.asarray(getattr(buffers, name), np.float32))
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    common = [*pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1", "--starts", "1",
              "--normal", files["normal"], "--light", files["light"], "--key", files["key"]]
    assert main(["fit", *common, "--fill-light", files["fill_light"], "--light-terms", "law,fill",
                 "--out", str(tmp_path / "fit")]) == 0
    stored = json.loads((tmp_path / "fit" / "params.json").read_text())["light_terms"]
    assert abs(stored["fill"] - 1.0) < 0.1 and "fill" in stored["psnr_without"]
    capsys.readouterr()
    # The fill without its buffer: one line naming it, nothing written.
    assert main(["fit", *common, "--light-terms", "law,fill", "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "invsss: error: --fill-light: the 'fill' term needs this buffer" in err and "Traceback" not in err

    params_path = str(tmp_path / "fit" / "params.json")
    scene = ["--image", str(paths["source"]), "--depth", str(paths["depth"]), "--mask", str(paths["mask"]),
             "--params", params_path, "--normal", files["normal"], "--light", files["light"], "--key", files["key"]]
    assert main(["render", *scene, "--out", str(tmp_path / "bad.exr")]) != 0
    err = capsys.readouterr().err
    assert "holds the 'fill' light term, which needs --fill-light" in err and "Traceback" not in err
    assert main(["render", *scene, "--fill-light", files["fill_light"], "--out", str(tmp_path / "lit.exr")]) == 0
    fitted, _ = invsss.read_params(params_path)
    read = {name: invsss.read_image(path) for name, path in files.items()}
    terms = LightTerms(law=stored["law"], law_strength=stored["law_strength"], fill=stored["fill"])
    expected = np.asarray(invsss.render(invsss.read_image(paths["source"]), depth, mask, fitted, light_terms=terms,
                                        light_buffers=LightBuffers(read["normal"], read["light"], read["key"],
                                                                   read["fill_light"])))
    np.testing.assert_allclose(invsss.read_image(tmp_path / "lit.exr"), expected, atol=1e-5)
    capsys.readouterr()
    assert main(["export", params_path, "--format", "hlsl"]) == 0
    assert "invsssOtherLightLaw" in capsys.readouterr().out
