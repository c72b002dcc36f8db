"""A sweep with ``saturation = "auto"`` leaves an integer target's top code out, as
``invsss fit`` does."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from tests.forward._clipped_card import PROFILE
from tests.io._clipped_card import card_on_disk


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_a_sweep_with_saturation_auto_leaves_the_top_code_out(tmp_path):
    import invsss.sweeps as ex

    paths, _ = card_on_disk(tmp_path, ".png")
    files = "\n".join(f'{role} = "{paths[role].name}"' for role in ("source", "target", "depth", "mask"))
    experiment = tmp_path / "card.toml"
    experiment.write_text(f"""
task = "fit"
[data]
[[data.files]]
name = "card"
{files}
[base]
profile = {{weights = {PROFILE['weights']}, variances = {PROFILE['variances']}}}
fix = {{correction = 0.0, maxdd = 1.0}}
n_starts = 1
[grid]
saturation = ["auto", 0.5]
""")
    summary = ex.run(experiment, tmp_path / "out", log=None)
    assert (summary.done, summary.failed) == (2, 0)
    rows = ex.results(tmp_path / "out", frame=False)
    top = int(np.sum(invsss.read_image(paths["target"]) >= 1.0))
    half = int(np.sum(invsss.read_image(paths["target"]) >= 0.5))
    by_count = {count: [row for row in rows if any(f"{count} masked pixel(s) at or above the saturation level "
                                                   f"{level} " in w for w in row["warnings"])]
                for count, level in ((top, "1"), (half, "0.5"))}
    assert len(by_count[top]) == 1 and len(by_count[half]) == 1
    assert abs(by_count[top][0]["param.sss_level"] / 375.0 - 1.0) < 0.02
