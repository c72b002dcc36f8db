"""Pairs on disk for the command-line tests: write one, and name it to ``invsss fit``."""

from __future__ import annotations

import numpy as np

import invsss

ROLES = ("source", "target", "depth", "mask")


def write_pair(folder, name, arrays) -> dict:
    """Write ``arrays`` (source, target, depth, mask) as ``NAME_<role>.exr`` (the mask as
    ``.png``) in ``folder``; return ``{role: path}``."""
    paths = {}
    for role, array in zip(ROLES, arrays):
        paths[role] = folder / f"{name}_{role}{'.png' if role == 'mask' else '.exr'}"
        invsss.write_image(paths[role], np.asarray(array, np.float32))
    return paths


def pair_args(*pairs) -> list[str]:
    """``--source S --target T --depth D --mask M`` for each ``{role: path}`` in ``pairs``."""
    return [arg for paths in pairs for role in ROLES for arg in (f"--{role}", str(paths[role]))]
