"""``invsss export --with-shader``: the reference shader written beside the constants
compiles with glslangValidator without a message, for every model and light term, and
the option needs HLSL and a file. (The resolution rule: tests/io/test_shader_export.py.)"""

from __future__ import annotations

import os

import pytest

from invsss import InvalidInputError
from invsss.cli import main
from invsss.io.export import export_params
from invsss.shaders import MODEL_SHADERS, compile_entry, shader_sources
from tests.io._shaders import needs_compiler, params_file

#: Entry points and the constants they need (a file is built only where its constants exist).
ENTRIES = {
    "sog": [("invsss_sog.hlsl", "BlurPassCS"), ("invsss_sog.hlsl", "AccumulateCS")],
    "thesis": [("invsss_thesis.hlsl", "BlurPassCS")],
    "separable": [("invsss_separable.hlsl", "SeparablePassCS")],
}
LIGHT_ENTRIES = [("invsss_law.hlsl", "LawCS"), ("invsss_light_terms.hlsl", "LightTermsCS")]


@needs_compiler
@pytest.mark.parametrize("model", sorted(ENTRIES))
def test_cli_export_with_shader_compiles_without_a_message(tmp_path, model, capsys):
    params = params_file(tmp_path / "params.json", model)
    out = tmp_path / "shader" / "skin_constants.hlsl"
    out.parent.mkdir()
    assert main(["export", str(params), "--format", "hlsl", "--out", str(out), "--with-shader"]) == 0
    assert "reference shader" in capsys.readouterr().out
    # The model's files and the light terms' (the fit uses them), not the other models'.
    written = {*shader_sources(model=model), *(file for file, _ in LIGHT_ENTRIES)}
    assert sorted(os.listdir(out.parent)) == sorted([out.name, *written])
    assert out.read_text() == export_params(params, format="hlsl")
    # The shader includes the constants under the name they were written to.
    own = (out.parent / MODEL_SHADERS[model][0]).read_text()
    assert '#include "skin_constants.hlsl"' in own and '#include "invsss_constants.hlsl"' not in own
    for file, entry in ENTRIES[model] + LIGHT_ENTRIES:
        # -I a folder without the constants: only the written file's own folder resolves them.
        _, messages = compile_entry(out.parent / file, entry, tmp_path)
        assert messages == "", (file, entry, messages)


def test_with_shader_needs_hlsl_and_a_file(tmp_path, capsys):
    params = params_file(tmp_path / "params.json", "sog")
    with pytest.raises(InvalidInputError, match="with_shader"):
        export_params(params, None, "hlsl", with_shader=True)
    with pytest.raises(InvalidInputError, match="with_shader"):
        export_params(params, tmp_path / "c.json", "json", with_shader=True)
    assert main(["export", str(params), "--format", "hlsl", "--with-shader"]) != 0
    assert not (tmp_path / "invsss_sog.hlsl").exists()
