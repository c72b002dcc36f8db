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


def write_pair_folder(folder, arrays, buffers=None, roles=("normal", "light")) -> None:
    """Write a pair folder as ``invsss scene`` lays it out (``source.exr`` ... ``mask.png``),
    with the named ``roles`` of an :class:`invsss.LightBuffers` as ``<role>.exr``."""
    folder.mkdir(parents=True, exist_ok=True)
    for role, array in zip(ROLES, arrays):
        invsss.write_image(folder / f"{role}{'.png' if role == 'mask' else '.exr'}", np.asarray(array, np.float32))
    for role in roles if buffers is not None else ():
        invsss.write_image(folder / f"{role}.exr", np.asarray(getattr(buffers, role), np.float32))


def light_sweep_text(grid: str) -> str:
    """An experiment file fitting every pair folder under ``data/`` with a two-Gaussian
    profile, one start and plain least squares, over ``[grid] light_terms = <grid>``."""
    return ('task = "fit"\n[data]\npairs = ["data/*/"]\n[base]\nn_starts = 1\nrobust = "none"\n'
            'profile = {weights = [0.5, 0.5], variances = [0.5, 2.0]}\nfix = {correction = 0.0, maxdd = 1.0}\n'
            f'[grid]\nlight_terms = {grid}\n')
