"""A params file from before the depth unit was recorded (issue 46) is read as for depth
in mm, with a notice."""

from __future__ import annotations

import json

import numpy as np
import pytest

import invsss
from invsss.validation import InputNotice

D = np.array([1.1, 0.55, 0.3])  # mm


BURLEY = {"sss_level": 800.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0, 1.0, 1.0],
          "variances": (D**2).tolist(), "model": "burley"}


def test_a_fit_file_from_before_the_unit_gets_a_notice(tmp_path):
    path = tmp_path / "old.json"
    path.write_text(json.dumps({"schema_version": 1, **BURLEY, "gauge": "variances", "converged": True}))
    with pytest.warns(InputNotice, match="reading its parameters as for depth in mm"):
        invsss.read_params(path)
