"""Tiny generated pairs and experiment files for the sweep tests (tests/sweeps/test_sweep.py,
tests/cli/test_sweep.py)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import invsss
import invsss.sweeps as ex
from invsss.io.result_dir import result_state
from invsss.sweeps.runner import trial_folder

#: The parameters the pairs are rendered with, and a profile to fit them.
TRUTH = invsss.SSSParams(600.0, 800.0, 0.5, [0.6, 0.4], [0.5, 2.0])
PROFILE = '{weights = [0.5, 0.5], variances = [0.5, 2.0]}'


def write_small_pair(folder, seed, size=24):
    """A 24 x 24 pair folder rendered at TRUTH with a NIR-like grey target."""
    os.makedirs(folder, exist_ok=True)
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size]
    source = rng.uniform(0.2, 1.0, (size, size, 3)).astype(np.float32)
    depth = (500.0 + 2.0 * x + rng.uniform(0.0, 1.0, (size, size))).astype(np.float32)
    mask = (((x - size / 2) ** 2 + (y - size / 2) ** 2) < (size * 0.42) ** 2).astype(np.float32)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH))
    grey = target @ np.array([0.6, 0.3, 0.1]) * 0.8 + 0.01  # a NIR-like grey target
    invsss.write_image(os.path.join(folder, "source.exr"), source)
    invsss.write_image(os.path.join(folder, "target.exr"), grey.astype(np.float32))
    invsss.write_image(os.path.join(folder, "depth.exr"), depth)
    invsss.write_image(os.path.join(folder, "mask.png"), mask)


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """A folder with pairs ``data/a``, ``data/b``, ``data/c`` (experiment files go beside ``data``)."""
    base = tmp_path_factory.mktemp("sweep")
    for seed, name in enumerate("abc"):
        write_small_pair(base / "data" / name, seed)
    return base


def experiment_file(root, name, text):
    """``text`` written as the experiment file ``root/name``."""
    path = root / name
    path.write_text(text)
    return path


RENDER = f"""
name = "matrix"
task = "render"
[data]
pairs = ["data/*/"]
[base]
maxdd = 0.5
profile = {PROFILE}
[grid]
sss_level = [300, 600]
correction = [0, 800]
"""


def rows_by_id(out):
    """The sweep's result rows by trial id."""
    return {row["id"]: row for row in ex.results(out, frame=False)}


def check_artefacts_match(out, rows):
    """Every done row has its committed files, whose params.json is the row's; nothing else."""
    folders = set(os.listdir(os.path.join(out, "trials"))) if os.path.isdir(os.path.join(out, "trials")) else set()
    done = {i for i, row in rows.items() if row["status"] == "done"}
    assert folders == done
    for trial_id in done:
        folder = trial_folder(out, trial_id)
        assert result_state(folder) == "complete"
        written = json.load(open(os.path.join(folder, "params.json")))
        for name in ("sss_level", "correction", "maxdd", "weights", "variances"):
            assert written[name] == rows[trial_id][f"param.{name}"]
        assert written["psnr"] == pytest.approx(rows[trial_id]["psnr"], rel=1e-12)
