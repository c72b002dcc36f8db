"""A params file whose numbers float32 would round (the export tests of io and the command line)."""

from __future__ import annotations

import pytest

from invsss.io import write_params


@pytest.fixture
def params_file(tmp_path):
    """A thesis-model params.json in ``tmp_path``."""
    path = tmp_path / "params.json"
    # Numbers that float32 would round: the export must carry the file's values.
    write_params(path, {"sss_level": 612.345678901, "correction": 2.0, "maxdd": 0.1,
                        "weights": [0.25, 0.75], "variances": [0.123456789012, 1.5],
                        "model": "thesis", "loss": 0.5})
    return path
