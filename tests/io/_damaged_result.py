"""A committed result whose manifest was then garbled, for the tests of damaged results."""

from __future__ import annotations

import json

import invsss
from invsss.io.result_dir import MANIFEST_NAME, ResultDir

PARAMS = {"sss_level": 600.0, "correction": 300.0, "maxdd": 0.02,
          "weights": [0.4, 0.6], "variances": [0.3, 1.5]}


def damaged_result(tmp_path):
    """A committed result whose manifest was then overwritten with text that is not JSON."""
    out = tmp_path / "result"
    with ResultDir(out) as directory:
        directory.commit({"params.json": lambda path: open(path, "w").write(json.dumps(PARAMS))})
    assert invsss.read_params(out / "params.json")  # whole, it reads
    (out / MANIFEST_NAME).write_text('{"state": "compl')
    return out
