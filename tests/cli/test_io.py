"""Files through the command line and the estimator: ``invsss render`` warns once about
values a fit left undetermined, and a mask over the whole frame is noted by load_pair
and by the estimator, each once."""

from __future__ import annotations

import numpy as np

import invsss
from tests.forward._notices import input_notices
from tests.io._scene_files import H, W, fitted_params_file, scene_files


def test_cli_render_warns_once_about_filled_values(tmp_path, capsys):
    from invsss.cli import main

    path = fitted_params_file(tmp_path, with_estimate=True)
    rng = np.random.default_rng(3)
    invsss.write_image(tmp_path / "image.exr", rng.random((12, 10, 3)).astype(np.float32))
    invsss.write_image(tmp_path / "depth.exr", np.full((12, 10), 500.0, np.float32))
    invsss.write_image(tmp_path / "mask.exr", np.ones((12, 10), np.float32))
    code = main(["render", "--image", str(tmp_path / "image.exr"), "--depth", str(tmp_path / "depth.exr"),
                 "--mask", str(tmp_path / "mask.exr"), "--params", str(path), "--out", str(tmp_path / "o.exr")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 0
    assert err == [f"invsss: warning: {path}: maxdd, weights[1], weights[2] not determined by the fit; "
                   "using its point estimate"]


def test_a_mask_over_the_whole_frame_is_noted_by_load_pair_and_the_estimator(tmp_path):
    from invsss.estimator.inputs import prepare_pair

    paths = scene_files(tmp_path)  # its mask is all ones
    notes = input_notices(lambda: invsss.load_pair(*(paths[k] for k in ("source", "target", "depth", "mask"))))
    assert notes == [f"{paths['mask']}: covers 100% of the frame; it likely includes background "
                     "(the mask should select skin only)"]
    image, depth = np.ones((H, W, 3)), np.full((H, W), 500.0)
    notes = input_notices(lambda: prepare_pair(image, image, depth, np.ones((H, W))))
    assert len(notes) == 1 and notes[0].startswith("mask: covers 100%")
    assert input_notices(lambda: prepare_pair(image, image, depth, None)) == []  # None: every pixel, asked for
