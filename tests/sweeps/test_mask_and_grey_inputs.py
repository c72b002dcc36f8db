"""A sweep reads masks stored with codes 0 and 1 and grey targets stored as three
identical channels as load_pair does (issue 30, cases 1 and 2)."""

from __future__ import annotations

import numpy as np

import invsss
import invsss.sweeps as ex
from tests.io._mask_and_grey import H, W, grey_image, skin_rect, write_codes


def test_a_sweep_reads_0_1_masks_and_grey_rgb_targets_as_load_pair_does(tmp_path):
    rng = np.random.default_rng(6)
    y, x = np.mgrid[0:H, 0:W]
    for name in ("plain", "stored"):
        folder = tmp_path / "data" / name
        folder.mkdir(parents=True)
        invsss.write_image(folder / "source.exr", rng.uniform(0.2, 1.0, (H, W, 3)).astype(np.float32)
                           if name == "plain" else invsss.read_image(tmp_path / "data" / "plain" / "source.exr"))
        invsss.write_image(folder / "depth.exr", (500.0 + 2.0 * x + 0.5 * y).astype(np.float32))
        grey = grey_image()
        if name == "plain":
            invsss.write_image(folder / "target.exr", grey)
            write_codes(folder / "mask.png", skin_rect().astype(np.uint8) * 255, "uint8")
        else:
            invsss.write_image(folder / "target.exr", np.repeat(grey[..., None], 3, 2))
            write_codes(folder / "mask.png", skin_rect().astype(np.uint8), "uint8")
    experiment = tmp_path / "e.toml"
    experiment.write_text('task = "render"\n[data]\npairs = ["data/*/"]\n[base]\ncorrection = 300.0\n'
                          'maxdd = 0.02\nprofile = {weights = [0.4, 0.6], variances = [0.3, 1.5]}\n'
                          '[grid]\nsss_level = [600.0]\n')
    summary = ex.run(experiment, tmp_path / "out", log=None)
    assert (summary.done, summary.failed) == (2, 0)
    rows = {row["pair"]: row for row in ex.results(tmp_path / "out", frame=False)}
    assert rows["stored"]["psnr"] == rows["plain"]["psnr"]
    notes = rows["stored"]["warnings"]
    assert any(n.startswith("data/stored/mask.png: mask codes are 0 and 1") or
               "stored/mask.png: mask codes are 0 and 1" in n for n in notes)
    assert any("stored/target.exr: its three channels are identical" in n for n in notes)
