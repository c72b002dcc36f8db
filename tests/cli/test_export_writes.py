"""``invsss export`` and ``invsss sweep-report`` lose nothing when they write (issue 46).

Every misuse is one line on standard error with exit code 2 and leaves the files
there as they were: an existing ``--out`` or shader file without ``--overwrite``, a
folder where a file goes, a folder that cannot be written to, a wrong ``--albedo``,
a burley fit of two shape parameters. ``--with-shader`` writes the fit's own
model's shader files (and its light terms'), named on standard output.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.shaders import shader_sources
from tests.io._export_files import listing, params_file

#: A file name the file system refuses (over 255 bytes), whoever runs the tests:
#: an OSError that permissions (ignored by root) do not decide.
TOO_LONG = "x" * 300 + ".json"


def _error(capsys) -> str:
    """The one line on standard error, checked to be one line without a traceback."""
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert "Traceback" not in err and len(lines) == 1, err
    assert lines[0].startswith("invsss: error: "), err
    return lines[0]


# ------------------------------------------------------------- existing files


def test_an_existing_out_file_is_kept_without_overwrite(tmp_path, capsys):
    params = params_file(tmp_path / "params.json")
    out = tmp_path / "c.json"
    out.write_text("mine\n")
    assert main(["export", params, "--out", str(out)]) == 2
    line = _error(capsys)
    assert str(out) in line and "--overwrite" in line
    assert out.read_text() == "mine\n"
    assert main(["export", params, "--out", str(out), "--overwrite"]) == 0
    assert json.loads(out.read_text())["model"] == "sog"


def test_edited_shader_files_are_kept_without_overwrite(tmp_path, capsys):
    params = params_file(tmp_path / "params.json")
    out = tmp_path / "c.hlsl"
    edited = tmp_path / "invsss_sog.hlsl"
    edited.write_text("// my edits\n")
    assert main(["export", params, "--format", "hlsl", "--out", str(out), "--with-shader"]) == 2
    line = _error(capsys)
    assert str(edited) in line and "--overwrite" in line
    # Nothing of the set is written: not the constants, not the other shader files.
    assert listing(tmp_path) == {"params.json": (tmp_path / "params.json").read_bytes(),
                                  "invsss_sog.hlsl": b"// my edits\n"}
    assert main(["export", params, "--format", "hlsl", "--out", str(out), "--with-shader", "--overwrite"]) == 0
    assert edited.read_text() == shader_sources("c.hlsl", model="sog")["invsss_sog.hlsl"]


def test_overwrite_without_out_is_refused(tmp_path, capsys):
    assert main(["export", params_file(tmp_path / "params.json"), "--overwrite"]) == 2
    assert "--overwrite" in _error(capsys)


# ------------------------------------------------------------- folders in the way


def test_out_naming_a_folder_is_one_line(tmp_path, capsys):
    params = params_file(tmp_path / "params.json")
    folder = tmp_path / "shader"
    folder.mkdir()
    assert main(["export", params, "--out", str(folder)]) == 2
    line = _error(capsys)
    assert str(folder) in line and "is a folder" in line
    assert main(["export", params, "--out", str(folder), "--overwrite"]) == 2  # not even with it
    _error(capsys)
    assert list(folder.iterdir()) == []


def test_a_shader_name_taken_by_a_folder_leaves_no_half_set(tmp_path, capsys):
    params = params_file(tmp_path / "params.json")
    (tmp_path / "invsss_seven_tap.hlsl").mkdir()
    out = tmp_path / "c.hlsl"
    before = listing(tmp_path)
    assert main(["export", params, "--format", "hlsl", "--out", str(out), "--with-shader", "--overwrite"]) == 2
    line = _error(capsys)
    assert str(tmp_path / "invsss_seven_tap.hlsl") in line and "shader file" in line
    assert listing(tmp_path) == before


# ------------------------------------------------------------- folders that refuse writes


def test_out_in_a_folder_that_is_a_file_is_one_line(tmp_path, capsys):
    params = params_file(tmp_path / "params.json")
    (tmp_path / "plain").write_text("")
    assert main(["export", params, "--out", str(tmp_path / "plain" / "c.json")]) == 2
    assert "is a file, not a folder" in _error(capsys)


def test_a_write_the_file_system_refuses_is_one_line(tmp_path, capsys):
    params = params_file(tmp_path / "params.json")
    assert main(["export", params, "--out", str(tmp_path / TOO_LONG)]) == 2
    assert "cannot write" in _error(capsys)
    assert listing(tmp_path) == {"params.json": (tmp_path / "params.json").read_bytes()}


def test_out_in_a_read_only_folder_is_one_line(tmp_path, capsys):
    params = params_file(tmp_path / "params.json")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("this user writes to read-only folders (root); the too-long name test covers the OSError")
        assert main(["export", params, "--format", "hlsl", "--out", str(locked / "c.hlsl"), "--with-shader"]) == 2
        assert "not writable" in _error(capsys)
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o755)


# ------------------------------------------------------------- the engines' and burley's inputs


def test_albedo_of_two_values_is_one_line(tmp_path, capsys):
    params = params_file(tmp_path / "params.json", "burley")
    assert main(["export", params, "--format", "unreal", "--albedo", "0.9/0.5"]) == 2
    line = _error(capsys)
    assert "--albedo" in line and "0.9/0.5" in line


@pytest.mark.parametrize("format", ["json", "hlsl"])
def test_a_burley_fit_of_two_shape_parameters_is_refused(tmp_path, capsys, format):
    path = tmp_path / "params.json"
    # Two channels' d^2: render and the engines' formats refuse it, so must these.
    path.write_text(json.dumps({"sss_level": 900.0, "correction": 0.0, "maxdd": 1.0, "model": "burley",
                                "weights": [1.0, 1.0], "variances": [1.21, 0.3025]}))
    assert main(["export", str(path), "--format", format, "--out", str(tmp_path / "c.txt")]) == 2
    assert "variances" in _error(capsys)
    assert not (tmp_path / "c.txt").exists()


# ------------------------------------------------------------- the model's shader only


@pytest.mark.parametrize("model", ["sog", "burley"])
def test_with_shader_writes_the_models_files_only_and_names_them(tmp_path, capsys, model):
    params = params_file(tmp_path / "params.json", model)
    out = tmp_path / "shader" / "c.hlsl"
    out.parent.mkdir()
    assert main(["export", params, "--format", "hlsl", "--out", str(out), "--with-shader"]) == 0
    files = list(shader_sources(model=model))
    assert sorted(os.listdir(out.parent)) == sorted(["c.hlsl", *files])
    said = capsys.readouterr().out
    assert f"{model} reference shader" in said and ", ".join(files) in said


def test_with_shader_adds_the_files_of_the_fits_light_terms(tmp_path, capsys):
    params = params_file(tmp_path / "params.json", "thesis",
                     light_terms={"shift": 1.2, "law": [0.93, 0.8, 0.7], "law_strength": 0.9})
    out = tmp_path / "shader" / "c.hlsl"
    out.parent.mkdir()
    assert main(["export", params, "--format", "hlsl", "--out", str(out), "--with-shader"]) == 0
    wanted = {*shader_sources(model="thesis"), "invsss_law.hlsl", "invsss_light_terms.hlsl"}
    assert set(os.listdir(out.parent)) == {"c.hlsl", *wanted}
    assert "invsss_sog.hlsl" not in capsys.readouterr().out


# ------------------------------------------------------------- sweep-report


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """A finished two-trial render sweep of an 8 x 8 pair (about a second)."""
    root = tmp_path_factory.mktemp("sweep")
    folder = root / "data" / "a"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    for name, image in [("source.exr", rng.uniform(0.2, 1, (8, 8, 3))), ("target.exr", rng.uniform(0.2, 1, (8, 8))),
                        ("depth.exr", np.full((8, 8), 500.0)), ("mask.png", np.ones((8, 8)))]:
        invsss.write_image(folder / name, image.astype(np.float32))
    experiment = root / "e.toml"
    experiment.write_text('name = "m"\ntask = "render"\n[data]\npairs = ["data/a/"]\n[base]\nmaxdd = 0.5\n'
                          'correction = 0\nprofile = {weights = [0.5, 0.5], variances = [0.5, 2.0]}\n'
                          '[grid]\nsss_level = [300, 600]\n')
    out = root / "out"
    assert main(["sweep", str(experiment), "--out", str(out)]) == 0
    return out


def test_sweep_report_with_a_file_in_the_way_of_its_folder_is_one_line(swept, capsys):
    report = swept / "report"
    report.write_text("not a folder\n")
    try:
        assert main(["sweep-report", str(swept), "--no-plots"]) == 2
        line = _error(capsys)
        assert str(report) in line and "in the way" in line
        assert report.read_text() == "not a folder\n"
    finally:
        report.unlink()


def test_sweep_report_in_a_read_only_folder_is_one_line(swept, capsys):
    assert main(["sweep-report", str(swept), "--no-plots"]) == 0
    capsys.readouterr()
    report = swept / "report"
    before = listing(report)
    report.chmod(0o555)
    try:
        if os.access(report, os.W_OK):
            pytest.skip("this user writes to read-only folders (root); the file-in-the-way test covers sweep-report")
        assert main(["sweep-report", str(swept)]) == 2
        assert "not writable" in _error(capsys)
        assert listing(report) == before
    finally:
        report.chmod(0o755)


def test_sweep_report_replaces_its_files_whole(swept, capsys):
    assert main(["sweep-report", str(swept)]) == 0
    assert main(["sweep-report", str(swept)]) == 0
    capsys.readouterr()
    names = sorted(listing(swept / "report"))
    assert names == ["metrics_vs_sss_level.png", "results.csv"]  # no temporaries left beside them
