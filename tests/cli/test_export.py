"""``invsss export``: the shader constants to stdout or a file, and its errors in one line."""

from __future__ import annotations

import json

from invsss.cli import main
from invsss.io.export import export_params
from tests.io._hlsl import parse_hlsl
from tests.io._params_files import params_file  # noqa: F401 (fixture)


def test_cli_export_to_stdout_and_file(params_file, tmp_path, capsys):
    assert main(["export", str(params_file), "--format", "hlsl"]) == 0
    printed = capsys.readouterr().out
    assert printed == export_params(params_file, format="hlsl")
    assert "// model: thesis" in printed and "passWidths" in parse_hlsl(printed)

    out = tmp_path / "sss.hlsl"
    args = ["export", str(params_file), "--model", "separable", "--taps", "11", "--format", "hlsl", "--out", str(out)]
    assert main(args) == 0
    assert str(out) in capsys.readouterr().out
    parsed = parse_hlsl(out.read_text())
    assert parsed["numTaps"] == ("int", 11) and len(parsed["kernel"][1]) == 11

    assert main(["export", str(params_file)]) == 0  # json by default
    assert json.loads(capsys.readouterr().out)["model"] == "thesis"


def test_cli_export_errors(params_file, tmp_path, capsys):
    missing = tmp_path / "missing.json"
    assert main(["export", str(missing)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("invsss: error:") and str(missing) in err and "Traceback" not in err
    assert main(["export", str(params_file), "--out", str(tmp_path / "no" / "dir.json")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["export", str(params_file), "--format", "glsl"]) == 2
    assert main(["export", str(params_file), "--model", "separable", "--taps", "4"]) == 2
    assert "taps" in capsys.readouterr().err
