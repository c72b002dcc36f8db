"""Files for the io tests: a pair of images, depth and mask on disk, and a params.json of a
fit that left some values undetermined."""

from __future__ import annotations

import json

import numpy as np

import invsss

H, W = 12, 16  # non-square, so a transposed read cannot pass


def scene_files(tmp_path, target_channels=1, sizes=None):
    """Source, target (``target_channels``), depth and mask files of H x W pixels, or of
    ``sizes[role]``; their paths by role."""
    sizes = sizes or {}
    rng = np.random.default_rng(2)
    paths = {k: tmp_path / f"{k}{ext}" for k, ext in
             [("source", ".exr"), ("target", ".exr"), ("depth", ".exr"), ("mask", ".png")]}
    hw = {k: sizes.get(k, (H, W)) for k in paths}
    invsss.write_image(paths["source"], rng.random((*hw["source"], 3)).astype(np.float32))
    target = rng.random((*hw["target"], target_channels)).astype(np.float32)
    invsss.write_image(paths["target"], target)
    invsss.write_image(paths["depth"], np.full(hw["depth"], 0.5, np.float32))
    invsss.write_image(paths["mask"], np.ones(hw["mask"], np.float32))
    return paths


def fitted_params_file(tmp_path, with_estimate):
    """A params.json whose maxdd and two weights the fit left undetermined, with the fit's
    point estimate of them if ``with_estimate``."""
    content = {
        "sss_level": 600.0, "correction": 800.0, "maxdd": None,
        "weights": [0.6, None, None], "variances": [0.5, 1.0, 1.01],
        "undetermined": ["maxdd", "weights[1]", "weights[2]"],
    }
    if with_estimate:
        content["estimate"] = {
            "sss_level": 600.0, "correction": 800.0, "maxdd": 0.25,
            "weights": [0.6, 0.3, 0.1], "variances": [0.5, 1.0, 1.01],
        }
    path = tmp_path / "params.json"
    path.write_text(json.dumps(content))
    return path
