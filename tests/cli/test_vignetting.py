"""The fitted vignetting field from the command line: ``invsss fit --vignetting``
writes the field into params.json, and the report's parameter lines show its corner
gain, on a model-made face photographed through a lens whose corners get 20 % less
light."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from tests.forward._vignetted_face import PROFILE3, photographs
from tests.io._pair_files import pair_args, write_pair


@pytest.fixture(scope="module")
def fits():
    """The fits of the photograph without vignetting, and of the one with it, fitting the field."""
    source, depth, mask, plain, shaded = photographs()
    kw = {"profile": PROFILE3, "n_starts": 2}
    return {
        "reference": invsss.fit_pair(source, plain, depth, mask, **kw),
        "shaded, fitted": invsss.fit_pair(source, shaded, depth, mask, vignetting=True, **kw),
    }


@pytest.mark.slow
def test_fitted_vignetting_recovers_the_unshaded_fit(fits):
    reference, fitted = fits["reference"], fits["shaded, fitted"]
    for name in ("sss_level", "correction", "maxdd"):
        value, ref = float(fitted.values[name]), float(reference.values[name])
        assert abs(value - ref) < reference.stderr[name], name
    record = fitted.vignetting
    a, err = np.asarray(record["coefficients"]), np.asarray(record["stderr"], dtype=float)
    assert np.all(np.abs(a - [-0.2, 0.0]) < 3 * err) and np.all(err < 0.05)
    assert record["corner_gain"] == pytest.approx(0.8, abs=0.02)
    # The same noise is left over (PSNR differs only through the darker peak).
    assert fitted.sigma == pytest.approx(reference.sigma, rel=0.02)
    assert fits["reference"].vignetting is None and fitted.to_dict()["vignetting"] == record
    from invsss.cli.report import parameter_lines

    shown = [line for line in parameter_lines(fitted) if line.startswith("vignetting:")]
    assert len(shown) == 1 and f"corner gain {record['corner_gain']:.3f}" in shown[0]
    assert not any(line.startswith("vignetting:") for line in parameter_lines(fits["reference"]))


@pytest.mark.slow
def test_cli_fit_writes_the_field_into_params_json(tmp_path):
    import json

    import invsss.cli

    source, depth, mask, _, photo = photographs()
    crop = slice(20, 60)  # a small fit: the flag's path through the CLI, not its accuracy
    files = write_pair(tmp_path, "crop", [image[crop, crop] for image in (source, photo, depth, mask)])
    (tmp_path / "profile.json").write_text(json.dumps(PROFILE3))
    arguments = ["fit", *pair_args(files), "--out", str(tmp_path / "out"), "--starts", "1", "--max-steps", "20",
                 "--vignetting", "--profile", str(tmp_path / "profile.json")]
    assert invsss.cli.main(arguments) == 0
    written = json.loads((tmp_path / "out" / "params.json").read_text())
    assert len(written["vignetting"]["coefficients"]) == 2 and written["vignetting"]["corner_gain"] < 1.0
    params, _ = invsss.read_params(tmp_path / "out" / "params.json")  # still a valid params file
    assert float(params.sss_level) > 0
