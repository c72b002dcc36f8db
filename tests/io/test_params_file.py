"""The params.json schema: strict numbers, versions, null filling, incomplete results."""

from __future__ import annotations

import json
import os
import warnings

import numpy as np
import pytest

import invsss
from invsss.io import PARAMS_KEYS, PARAMS_OPTIONAL_KEYS, read_params, write_params
from invsss.io.export import export_params
from invsss.io.params_file import MANIFEST_NAME, SCHEMA_VERSION, params_json_schema
from invsss.forward.params import PARAM_NAMES, check_plausible
from invsss.validation import InputNotice, InvalidInputError
from tests import ROOT

PARAMS = {"sss_level": 600.0, "correction": 250.0, "maxdd": 0.01,
          "weights": [0.3, 0.7], "variances": [0.5, 2.0]}
DOCS = ROOT / "docs"


def _file(tmp_path, content, name="params.json") -> str:
    path = tmp_path / name
    path.write_text(json.dumps(content))
    return str(path)


def _error(tmp_path, content) -> str:
    path = _file(tmp_path, content)
    with pytest.raises(InvalidInputError) as info:
        read_params(path)
    message = str(info.value)
    assert message.startswith(path + ": ") and "\n" not in message
    return message[len(path) + 2:]


# ------------------------------------------------------------------- numbers


@pytest.mark.parametrize(
    "change, expected",
    [
        ({"sss_level": True}, "sss_level: expected a number, got true"),
        ({"sss_level": False}, "sss_level: expected a number, got false"),
        ({"sss_level": "600"}, 'sss_level: expected a number, got "600"'),
        ({"maxdd": [0.01]}, "maxdd: expected a number, got [0.01]"),
        ({"weights": [0.3, True]}, "weights[1]: expected a number, got true"),
        ({"weights": [[0.3, 0.2, 0.1], [0.7, "0.8", 0.9]]}, 'weights[1][1]: expected a number, got "0.8"'),
        ({"variances": "0.5, 2.0"}, 'variances: expected a list of numbers, got "0.5, 2.0"'),
        ({"estimate": {**PARAMS, "maxdd": True}}, "estimate.maxdd: expected a number, got true"),
        ({"interrupted": 1}, "interrupted: expected true or false, got 1"),
        ({"estimate": {k: v for k, v in PARAMS.items() if k != "maxdd"}}, "estimate.maxdd is missing"),
        ({"iterations": 2.5}, "iterations: expected an integer, got 2.5"),
    ],
)
def test_non_numbers_are_refused_naming_the_entry_and_value(tmp_path, change, expected):
    assert _error(tmp_path, {**PARAMS, **change}) == expected


def test_false_is_not_reported_as_zero(tmp_path):
    message = _error(tmp_path, {**PARAMS, "correction": False})
    assert "false" in message and "got 0" not in message


def test_mismatched_lengths_are_refused(tmp_path):
    message = _error(tmp_path, {**PARAMS, "weights": [0.2, 0.3, 0.5],
                                "variances": [0.1, 0.5, 1.0, 2.0, 4.0]})
    assert "3 weights" in message and "5 variances" in message


def test_ragged_per_channel_weights_are_refused(tmp_path):
    assert "rectangular" in _error(tmp_path, {**PARAMS, "weights": [[0.3, 0.2], [0.7]]})


def test_unknown_key_suggests_the_likely_one(tmp_path):
    message = _error(tmp_path, {**PARAMS, "intterupted": True})
    assert "unknown key 'intterupted' (did you mean 'interrupted'?)" in message


# ------------------------------------------------------------------- versions


def test_write_params_writes_the_schema_version_first(tmp_path):
    path = tmp_path / "p.json"
    write_params(path, PARAMS)
    content = json.loads(path.read_text())
    assert list(content)[0] == "schema_version" and content["schema_version"] == SCHEMA_VERSION
    params, extras = read_params(path)
    assert "schema_version" not in extras
    np.testing.assert_allclose(np.asarray(params.weights), PARAMS["weights"], rtol=1e-6)


def test_a_file_without_version_still_loads(tmp_path):
    params, _ = read_params(_file(tmp_path, PARAMS))
    assert float(params.sss_level) == 600.0


def test_a_newer_version_says_what_to_do(tmp_path):
    message = _error(tmp_path, {**PARAMS, "schema_version": SCHEMA_VERSION + 1, "new_key": 1})
    assert "newer invsss" in message and "upgrade invsss" in message


@pytest.mark.parametrize("version", [0, True, "1", 1.0])
def test_a_bad_version_is_refused(tmp_path, version):
    assert _error(tmp_path, {**PARAMS, "schema_version": version}).startswith("schema_version:")


def test_write_params_refuses_what_read_params_would(tmp_path):
    path = tmp_path / "p.json"
    with pytest.raises(InvalidInputError, match="sss_level: expected a number, got true"):
        write_params(path, {**PARAMS, "sss_level": True})
    with pytest.raises(InvalidInputError, match="did you mean 'converged'"):
        write_params(path, {**PARAMS, "convergd": True})
    # Values, not only the schema: each of these was written and then refused on reading.
    for bad, message in [({"sss_level": float("nan")}, "sss_level contains NaN"),
                         ({"sss_level": -5.0}, "sss_level must be > 0, got -5"),
                         ({"variances": [-2.0] * len(PARAMS["variances"])}, "variances must be >= 0"),
                         ({"weights": [1.0, 2.0], "variances": [1.0]}, "weights must have shape"),
                         ({"sss_level": None}, "sss_level is null")]:
        with pytest.raises(InvalidInputError, match=message):
            write_params(path, {**PARAMS, **bad})
        with pytest.raises(InvalidInputError, match=message):
            path.write_text(json.dumps({**PARAMS, **bad}))
            read_params(path)
        path.unlink()
    assert not path.exists()


def test_a_fit_result_round_trips_with_every_report_key(tmp_path):
    report = {
        "model": "sog", "depth_unit": "cm", "tap_weights": "jimenez", "stderr": {"sss_level": 1.0}, "undetermined": [],
        "loss": 0.1, "psnr": 40.0, "ssim": 0.99, "converged": True, "interrupted": False,
        "iterations": 7, "fixed": {}, "gauge": "variances", "channels_mix": [0.3, 0.6, 0.1],
        "gain": [1.0], "offset": [0.0], "profile": "thesis-nir", "estimate": PARAMS,
        "sigma": 0.01, "solver": "lm", "warnings": ["w"],
        "alignment": [{"kind": "translation", "shift_px": [1.0, -0.5], "centre_px": [10.0, 12.0],
                       "matrix": [[1.0, 0.0, 1.0], [0.0, 1.0, -0.5]]}],
        "vignetting": {"model": "gain field", "coefficients": [-0.2, 0.01], "stderr": [0.004, None],
                       "corner_gain": 0.81},
        "highlights": {"method": "residual", "excluded_pixels": [12], "fraction": [0.01]},
        "light_terms": {"shift": 1.3, "grazing": 0.2, "stderr": {"shift": 0.1, "grazing": None}},
        "inputs": {"pairs": [{"depth": {"kind": "distance", "distance_mm": 600.0},
                              "mask": {"kind": "made from the pair", "file": "mask_used.png"}}],
                   "held": {"correction": {"value": 0.0, "why": "constant depth"}}},
        "blur": {"sigma_px": [0.32], "stderr_px": [0.036], "depth": 600.0, "slope": 0.6, "resolved": False},
        "pigment": {"degree": 1, "terms": ["u", "v"], "coefficients": [[0.1], [-0.05]], "stderr": [[0.01], [None]],
                    "psnr_without": 25.0},
    }
    path = tmp_path / "p.json"
    write_params(path, {**PARAMS, **report})
    _, extras = read_params(path)
    assert extras == report
    assert set(PARAMS_OPTIONAL_KEYS) == set(report) | {"schema_version"}
    assert PARAMS_KEYS == PARAM_NAMES


# --------------------------------------------------------------- null filling


def _fit_file(tmp_path, weights):
    content = {**PARAMS, "weights": weights, "variances": [0.5, 1.0, 2.0, 4.0],
               "undetermined": ["weights[2]", "weights[3]"],
               "estimate": {**PARAMS, "weights": [0.1, 0.2, 0.3, 0.4], "variances": [0.5, 1.0, 2.0, 4.0]}}
    return _file(tmp_path, content)


def test_only_the_null_entries_are_filled_and_named(tmp_path):
    path = _fit_file(tmp_path, [0.5, 0.25, None, None])
    with pytest.warns(UserWarning) as caught:
        params, extras = read_params(path)
    messages = [str(w.message) for w in caught]
    assert messages == [f"{path}: weights[2], weights[3] not determined by the fit; using its point estimate"]
    np.testing.assert_allclose(np.asarray(params.weights), [0.5, 0.25, 0.3, 0.4], rtol=1e-6)
    assert extras["filled_from_estimate"] == ["weights[2]", "weights[3]"]


def test_entries_the_files_model_does_not_use_are_filled_without_a_warning(tmp_path):
    """A burley fit's weights do not enter its image: filling them is no news to a renderer."""
    path = tmp_path / "params.json"
    content = json.loads(open(_fit_file(tmp_path, [0.5, 0.25, None, None])).read())
    path.write_text(json.dumps({**content, "model": "burley"}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        params, extras = read_params(path)
    np.testing.assert_allclose(np.asarray(params.weights), [0.5, 0.25, 0.3, 0.4], rtol=1e-6)
    assert extras["filled_from_estimate"] == ["weights[2]", "weights[3]"]
    # Exported with a model that uses them (export --model sog), the warning comes back.
    with pytest.warns(UserWarning, match="weights\\[2\\], weights\\[3\\] not determined by the burley fit; "
                      "model sog uses them"):
        export_params(path, None, "json", model="sog")
    path.write_text(json.dumps({**content, "model": "sog"}))  # sog uses them: the warning stays
    with pytest.warns(UserWarning, match="weights\\[2\\], weights\\[3\\] not determined"):
        read_params(path)


def test_two_edits_of_determined_entries_give_different_params(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a, _ = read_params(_fit_file(tmp_path, [0.5, 0.25, None, None]))
        b, _ = read_params(_fit_file(tmp_path, [0.9, 0.25, None, None]))
    assert not np.allclose(np.asarray(a.weights), np.asarray(b.weights))


def test_per_channel_nulls_are_filled_entry_by_entry(tmp_path):
    estimate = {**PARAMS, "weights": [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]}
    path = _file(tmp_path, {**PARAMS, "weights": [[0.9, None, 0.3], [0.4, 0.5, None]], "estimate": estimate})
    with pytest.warns(UserWarning, match=r"weights\[0,1\], weights\[1,2\] not determined"):
        params, _ = read_params(path)
    np.testing.assert_allclose(np.asarray(params.weights), [[0.9, 0.2, 0.3], [0.4, 0.5, 0.6]], rtol=1e-6)


def test_an_estimate_of_another_shape_cannot_fill(tmp_path):
    path = _file(tmp_path, {**PARAMS, "weights": [0.3, None], "estimate": {**PARAMS, "weights": [0.1, 0.2, 0.7]}})
    with pytest.raises(InvalidInputError, match=r"estimate.weights has shape \(3,\)"):
        read_params(path)


# ---------------------------------------------------------- incomplete results


@pytest.mark.parametrize("state", ["incomplete", None, "garbage"])
def test_params_of_an_incomplete_result_are_refused(tmp_path, state):
    path = _file(tmp_path, PARAMS)
    manifest = {"state": state} if state != "garbage" else "not an object"
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(manifest))
    message = _error(tmp_path, PARAMS)
    if state == "garbage":
        # A manifest that is not a JSON object is damaged, not "interrupted" (issue 30).
        assert message == (f"its result's manifest {tmp_path / MANIFEST_NAME} is damaged (not a JSON object), "
                           "so whether the result is whole is unknown; re-run it")
    else:
        assert message == "belongs to an incomplete result (the run that wrote it was interrupted); re-run it"
    assert os.path.exists(path)


def test_params_of_a_complete_result_load(tmp_path):
    path = _file(tmp_path, PARAMS)
    (tmp_path / MANIFEST_NAME).write_text(json.dumps({"state": "complete", "files": ["params.json"]}))
    params, _ = read_params(path)
    assert float(params.maxdd) == pytest.approx(0.01)


# ------------------------------------------------------------- published schema


def test_published_schema_is_the_generated_one():
    published = json.loads((DOCS / "params-schema.json").read_text())
    assert published == params_json_schema()


def test_every_key_is_described_in_the_docs():
    text = (DOCS / "params-json.md").read_text()
    missing = [k for k in PARAMS_KEYS + PARAMS_OPTIONAL_KEYS if f"`{k}`" not in text]
    assert missing == []


# ----------------------------------------------------------------- plausibility


@pytest.mark.parametrize(
    "params, fragment",
    [
        (invsss.SSSParams(1e30, 0.0, 1.0, [1.0], [2.0]), r"sss_level 1e\+30 blurs by up to"),
        (invsss.SSSParams(1e-6, 0.0, 1.0, [1.0], [2.0]), "as narrow as"),
        (invsss.SSSParams(600.0, 1e30, 1e30, [1.0], [2.0]), r"maxdd 1e\+30 give passes as narrow"),
    ],
)
def test_absurd_blur_warns_naming_the_value(params, fragment):
    depth = np.full((16, 20), 500.0)
    depth[:, 10:] += np.arange(10) * 5.0  # a slope, for the correction to act on
    with pytest.warns(InputNotice, match=fragment):
        check_plausible(params, depth, "p.json")


def test_render_warns_when_depth_in_metres_meets_parameters_fitted_in_mm():
    # The stretch divides by depth: metres for mm make the blur 1000 times wider.
    params = invsss.SSSParams(600.0, 250.0, 0.01, [0.4, 0.6], [0.5, 4.0])
    image, mask = np.ones((16, 20, 3)), np.ones((16, 20))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        invsss.render(image, np.full((16, 20), 500.0), mask, params)
    with pytest.warns(InputNotice, match=r"params: sss_level 600 blurs by up to .* wider than the 16x20 image"):
        invsss.render(image, np.full((16, 20), 0.5), mask, params)


def test_ordinary_values_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert check_plausible(invsss.SSSParams(600.0, 250.0, 0.01, [1.0], [2.0]), np.full((16, 20), 500.0)) == []
