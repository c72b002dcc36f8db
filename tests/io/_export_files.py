"""Params files to export and a listing of what an export wrote, for the export-writing tests."""

from __future__ import annotations

import os

import invsss


def params_file(path, model="sog", **extra):
    """A small params file of ``model`` (burley: three shape parameters)."""
    if model == "burley":
        values = {"weights": [1.0, 1.0, 1.0], "variances": [1.21, 0.3025, 0.09]}
    else:
        values = {"weights": [0.3, 0.7], "variances": [2.0, 0.5]}
    invsss.write_params(path, {"sss_level": 900.0, "correction": 10.0, "maxdd": 1.0, "model": model,
                               **values, **extra})
    return str(path)


def listing(folder) -> dict:
    """Every file under ``folder`` with its bytes (hidden temporaries included)."""
    out = {}
    for directory, _, files in os.walk(folder):
        for name in files:
            path = os.path.join(directory, name)
            with open(path, "rb") as f:
                out[os.path.relpath(path, folder)] = f.read()
    return out
