"""Writing exported files from the library (invsss.io.export, invsss.io.writing): an
existing file is kept unless told, and a set of files whose later one fails leaves
none written."""

from __future__ import annotations

import pytest

from invsss import InvalidInputError
from invsss.io.export import export_params
from invsss.io.writing import write_texts_atomic
from tests.io._export_files import listing, params_file


def test_library_export_refuses_an_existing_file_unless_told(tmp_path):
    params = params_file(tmp_path / "params.json")
    out = tmp_path / "c.hlsl"
    out.write_text("mine\n")
    with pytest.raises(InvalidInputError, match="already exists"):
        export_params(params, out, "hlsl")
    assert out.read_text() == "mine\n"
    assert export_params(params, out, "hlsl", overwrite=True) == out.read_text()


def test_a_set_whose_later_file_fails_writes_none(tmp_path):
    # The second target's name is legal, its temporary's is not (over 255 bytes):
    # it fails after the first file's temporary is written, before any rename.
    first, second = tmp_path / "a.txt", tmp_path / ("y" * 250)
    first.write_text("old\n")
    with pytest.raises(InvalidInputError, match="cannot write"):
        write_texts_atomic({first: "new\n", second: "new\n"}, overwrite=True)
    assert listing(tmp_path) == {"a.txt": b"old\n"}
