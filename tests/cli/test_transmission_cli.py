"""The ``transmission`` light term from the command line (issue 48): ``invsss fit
--thickness --key-irradiance``, ``render`` with the same buffers, and the one-line errors."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightTerms
from tests.forward._backlit_scenes import backlit_dome

pytestmark = pytest.mark.usefixtures("float64")

TRUTH = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
PROFILE = {"weights": [0.5, 0.5], "variances": [0.5, 2.0]}


def _files(tmp_path):
    from tests.io._pair_files import write_pair

    source, depth, mask, buffers = backlit_dome(size=32)
    terms = LightTerms(transmission=0.6, thickness_scale=0.1)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH, light_terms=terms, light_buffers=buffers))
    paths = write_pair(tmp_path, "backlit", (source, target, depth, mask))
    files = {}
    for name in ("normal", "light", "thickness", "key_irradiance"):
        files[name] = str(tmp_path / f"{name}.exr")
        invsss.write_image(files[name], np.asarray(getattr(buffers, name), np.float32))
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    return paths, files, profile


def _buffers(files):
    from invsss.forward.light_terms import LightBuffers

    return LightBuffers(normal=invsss.read_image(files["normal"]), light=invsss.read_image(files["light"]),
                        thickness=invsss.read_image(files["thickness"])[..., 0],
                        key_irradiance=invsss.read_image(files["key_irradiance"]))


def test_missing_or_misshapen_buffers_are_one_line_naming_the_flag_or_file(tmp_path, capsys):
    from invsss.cli import main
    from tests.io._pair_files import pair_args

    paths, files, profile = _files(tmp_path)
    common = [*pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1",
              "--normal", files["normal"], "--light", files["light"], "--light-terms", "transmission"]
    assert main(["fit", *common, "--key-irradiance", files["key_irradiance"], "--out", str(tmp_path / "a")]) != 0
    err = capsys.readouterr().err
    assert "invsss: error: --thickness: the 'transmission' term needs this buffer" in err and "Traceback" not in err
    invsss.write_image(tmp_path / "small.exr", np.zeros((8, 8), np.float32))
    assert main(["fit", *common, "--thickness", str(tmp_path / "small.exr"), "--key-irradiance",
                 files["key_irradiance"], "--out", str(tmp_path / "b")]) != 0
    err = capsys.readouterr().err
    assert "small.exr: expected a 1-channel image of the source's size (32, 32) for --thickness" in err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.slow
def test_cli_fit_and_render_with_the_transmission_buffers(tmp_path, capsys):
    from invsss.cli import main
    from tests.io._pair_files import pair_args

    paths, files, profile = _files(tmp_path)
    buffers = ["--normal", files["normal"], "--light", files["light"], "--thickness", files["thickness"],
               "--key-irradiance", files["key_irradiance"]]
    assert main(["fit", *pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1",
                 *buffers, "--light-terms", "transmission", "--out", str(tmp_path / "fit")]) == 0
    stored = json.loads((tmp_path / "fit" / "params.json").read_text())["light_terms"]
    assert stored["transmission"][0] == pytest.approx(0.6, rel=0.02)
    from invsss.cli.report import parameter_lines

    # The report prints the tint and the scale (the same fit from the library).
    fit = invsss.fit_pair(invsss.read_image(paths["source"]), invsss.read_image(paths["target"]),
                          invsss.read_depth(paths["depth"]), invsss.read_mask(paths["mask"]), profile=PROFILE,
                          fix={"correction": 0.0, "maxdd": 1.0}, light_terms="transmission",
                          light_buffers=_buffers(files))
    text = "\n".join(parameter_lines(fit))
    printed = re.search(r"light terms: transmission tint ([0-9.]+) .*thickness scale ([0-9.]+)/mm", text)
    assert printed is not None, text
    assert float(printed[1]) == pytest.approx(0.6, rel=0.02) and float(printed[2]) == pytest.approx(0.1, rel=0.02)
    assert stored["thickness_scale"] == pytest.approx(0.1, rel=0.02)
    # invsss render applies the fitted term, as the library does with the stored values.
    out = tmp_path / "rendered.exr"
    scene = ["--image", str(paths["source"]), "--depth", str(paths["depth"]), "--mask", str(paths["mask"])]
    assert main(["render", *scene, "--params", str(tmp_path / "fit" / "params.json"), *buffers,
                 "--out", str(out)]) == 0
    fitted = invsss.read_image(tmp_path / "fit" / "fit.exr")
    np.testing.assert_allclose(invsss.read_image(out), fitted, atol=2e-3)
