"""A params.json written by a fit and read back: its per-channel null entries are named
as the estimator names them (``weights[2,0]``)."""

from __future__ import annotations

import json

import pytest

from invsss.estimator.summary import entry_name
from invsss.io import read_params

PARAMS = {"sss_level": 600.0, "correction": 250.0, "maxdd": 0.01,
          "weights": [0.3, 0.7], "variances": [0.5, 2.0]}


def _file(tmp_path, content, name="params.json") -> str:
    path = tmp_path / name
    path.write_text(json.dumps(content))
    return str(path)


def test_per_channel_null_entries_are_named_as_the_fit_names_them(tmp_path):
    # A fit lists an RGB weight as "weights[2,0]" (entry_name); the filled list must match it.
    weights = [[0.5, 0.5, 0.5], [0.2, 0.2, 0.2], [None, 0.3, 0.3]]
    undetermined = [entry_name("weights", (2, 0))]
    path = _file(tmp_path, {**PARAMS, "weights": weights, "variances": [0.5, 1.0, 2.0], "undetermined": undetermined,
                            "estimate": {**PARAMS, "weights": [[0.5] * 3, [0.2] * 3, [0.3] * 3], "variances": [0.5, 1.0, 2.0]}})
    with pytest.warns(UserWarning, match=r"weights\[2,0\] not determined by the fit"):
        _, extras = read_params(path)
    assert extras["filled_from_estimate"] == undetermined == extras["undetermined"]
