"""The light-aware terms from the command line: ``invsss fit --light-terms`` with the
buffers, ``render`` applying the fitted terms, and params.json keeping them."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms
from tests.forward._lit_scenes import FIX, PROFILE, lit_card

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
def test_params_file_keeps_the_terms(tmp_path):
    source, depth, mask, buffers = lit_card(24)
    target = np.asarray(invsss.render(source, depth, mask, invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0]),
                                      light_terms=LightTerms(shift=1.0), light_buffers=buffers))
    fit = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1,
                          light_terms="shift", light_buffers=buffers)
    path = tmp_path / "params.json"
    invsss.write_params(path, fit.to_dict())
    import json

    stored = json.loads(path.read_text())["light_terms"]
    assert stored["shift"] == pytest.approx(fit.light_terms["shift"]) and "grazing" not in stored
    invsss.read_params(path)  # the strict params file accepts the new key


@pytest.mark.slow
def test_cli_fit_with_light_terms(tmp_path, capsys):
    import json

    from invsss.cli import main
    from tests.io._pair_files import pair_args, write_pair

    source, depth, mask, buffers = lit_card(32)
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=LightTerms(shift=1.2),
                                      light_buffers=buffers))
    paths = write_pair(tmp_path, "lit", (source, target, depth, mask))
    invsss.write_image(tmp_path / "light.exr", np.asarray(buffers.light, np.float32))
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    common = [*pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1", "--starts", "1"]
    assert main(["fit", *common, "--light-terms", "shift", "--light", str(tmp_path / "light.exr"),
                 "--out", str(tmp_path / "fit")]) == 0
    stored = json.loads((tmp_path / "fit" / "params.json").read_text())
    assert stored["light_terms"]["shift"] == pytest.approx(1.2, abs=0.05)
    # Asking for the term without its buffer is a one-line error, nothing written.
    capsys.readouterr()
    assert main(["fit", *common, "--light-terms", "shift", "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "invsss: error: --light: the 'shift' term needs this buffer" in err and "Traceback" not in err

    # invsss render applies the fitted terms: the library's render with the same
    # values, and not the blur alone.
    params_path = str(tmp_path / "fit" / "params.json")
    scene = ["--image", str(paths["source"]), "--depth", str(paths["depth"]), "--mask", str(paths["mask"]),
             "--params", params_path]
    assert main(["render", *scene, "--light", str(tmp_path / "light.exr"), "--out", str(tmp_path / "lit.exr")]) == 0
    assert "light terms shift=" in capsys.readouterr().out
    fitted, _ = invsss.read_params(params_path)
    expected = np.asarray(invsss.render(source, depth, mask, fitted,
                                        light_terms=LightTerms(shift=stored["light_terms"]["shift"]),
                                        light_buffers=LightBuffers(light=invsss.read_image(tmp_path / "light.exr"))))
    rendered = invsss.read_image(tmp_path / "lit.exr")
    np.testing.assert_allclose(rendered, expected.reshape(rendered.shape), atol=1e-5)
    assert main(["render", *scene, "--no-light-terms", "--out", str(tmp_path / "plain.exr")]) == 0
    plain = invsss.read_image(tmp_path / "plain.exr")
    assert np.abs(plain - rendered).max() > 1e-2
    # Terms in the params file without their buffer: one line naming the flag.
    capsys.readouterr()
    assert main(["render", *scene, "--out", str(tmp_path / "bad.exr")]) != 0
    err = capsys.readouterr().err
    assert "holds the 'shift' light term, which needs --light" in err and "Traceback" not in err
    # Two terms without any buffer: every missing flag in the one line, not one per attempt.
    both = json.loads(open(params_path).read())
    both["light_terms"].update(law=[0.9] * source.shape[-1], law_strength=1.0)
    (tmp_path / "both.json").write_text(json.dumps(both))
    two = [*scene[:-1], str(tmp_path / "both.json")]
    assert main(["render", *two, "--out", str(tmp_path / "bad.exr")]) != 0
    err = capsys.readouterr().err
    assert ("holds the 'shift' and 'law' light terms, which need --light, --key and --normal (or "
            "--no-light-terms") in err, err
