"""The ``law`` light term from the command line: ``invsss fit --key``, ``render`` and
``export`` with the key light's buffer, and the report's line of fitted albedos."""

from __future__ import annotations

import json

import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms
from tests.forward._lit_scenes import FIX, PROFILE, dome_with_two_lights, lit_target

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
def test_fit_recovers_an_albedo_per_channel_and_the_blur():
    source, depth, mask, buffers = dome_with_two_lights()
    truth = [0.95, 0.85, 0.7]
    target = lit_target(source, depth, mask, buffers, LightTerms(law=truth))
    fit = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2,
                          light_terms="law", light_buffers=buffers)
    assert fit.converged
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.02)
    fitted, errors = fit.light_terms["law"], fit.light_terms["stderr"]["law"]
    assert len(fitted) == len(errors) == 3 and fit.light_terms["fixed"] == []
    # Honest errors: each albedo within 4 of its standard errors of the truth.
    for w, err, true in zip(fitted, errors, truth):
        assert err is not None and 0 < err < 0.02 and abs(w - true) < 4 * err
    # The fitted values render as fitted: light_terms_params carries the albedos.
    np.testing.assert_allclose(np.asarray(fit.light_terms_params().law), fitted, rtol=1e-6)
    # Without the law the same data give a biased blur and a worse fit.
    plain = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2)
    assert plain.psnr < fit.psnr - 5.0
    from invsss.cli.report import parameter_lines

    assert "law albedo 0.9" in "\n".join(parameter_lines(fit))


@pytest.mark.slow
def test_cli_fit_and_render_with_the_key_buffer(tmp_path, capsys):
    from invsss.cli import main
    from tests.io._pair_files import pair_args, write_pair

    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.95, 0.85, 0.7]), noise=0.0)
    paths = write_pair(tmp_path, "lit", (source, target, depth, mask))
    files = {}
    for name in ("normal", "light", "key"):
        files[name] = str(tmp_path / f"{name}.exr")
        invsss.write_image(files[name], np.asarray(getattr(buffers, name), np.float32))
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    common = [*pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1", "--starts", "1",
              "--normal", files["normal"], "--light", files["light"]]
    assert main(["fit", *common, "--key", files["key"], "--light-terms", "law", "--out", str(tmp_path / "fit")]) == 0
    stored = json.loads((tmp_path / "fit" / "params.json").read_text())["light_terms"]
    # The strength trades against the albedos' common level (docs/model.md, section
    # 8): the truth lies within 4 of their standard errors.
    assert len(stored["stderr"]["law"]) == 3
    for w, err, true in zip(stored["law"], stored["stderr"]["law"], [0.95, 0.85, 0.7]):
        assert abs(w - true) < 4 * err
    assert abs(stored["law_strength"] - 1.0) < 0.1
    capsys.readouterr()
    # The law without --key: one line naming the buffer, nothing written.
    assert main(["fit", *common, "--light-terms", "law", "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "invsss: error: --key: the 'law' term needs this buffer" in err and "Traceback" not in err
    # A key of another channel count: one line naming the file.
    invsss.write_image(tmp_path / "grey_key.exr", np.asarray(buffers.key[..., 0], np.float32))
    assert main(["fit", *common, "--key", str(tmp_path / "grey_key.exr"), "--light-terms", "law",
                 "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "grey_key.exr: expected an image of the source's size and channels" in err and "Traceback" not in err

    # invsss render applies the fitted law: the library's render with the stored albedos.
    params_path = str(tmp_path / "fit" / "params.json")
    scene = ["--image", str(paths["source"]), "--depth", str(paths["depth"]), "--mask", str(paths["mask"]),
             "--params", params_path, "--normal", files["normal"], "--light", files["light"]]
    assert main(["render", *scene, "--key", files["key"], "--out", str(tmp_path / "lit.exr")]) == 0
    assert "light terms law=0.9" in capsys.readouterr().out
    fitted, _ = invsss.read_params(params_path)
    read = {name: invsss.read_image(path) for name, path in files.items()}
    expected = np.asarray(invsss.render(invsss.read_image(paths["source"]), depth, mask, fitted,
                                        light_terms=LightTerms(law=stored["law"],
                                                               law_strength=stored["law_strength"]),
                                        light_buffers=LightBuffers(read["normal"], read["light"], read["key"])))
    np.testing.assert_allclose(invsss.read_image(tmp_path / "lit.exr"), expected, atol=1e-5)
    assert main(["render", *scene, "--out", str(tmp_path / "bad.exr")]) != 0
    err = capsys.readouterr().err
    assert "holds the 'law' light term, which needs --key" in err and "Traceback" not in err
    # The exported shader carries the albedos.
    assert main(["export", params_path, "--format", "hlsl"]) == 0
    assert "lawAlbedo[3]" in capsys.readouterr().out
