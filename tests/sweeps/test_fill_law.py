"""A sweep with the ``fill`` light term reads a pair folder's fill_light.exr only for
the trials with the fill."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.validation import InvalidInputError
from tests.forward._lit_scenes import dome_with_two_lights

pytestmark = pytest.mark.usefixtures("float64")


def test_a_sweep_reads_fill_light_only_for_trials_with_the_fill(tmp_path):
    import invsss.sweeps as ex
    from tests.io._pair_files import light_sweep_text, write_pair_folder

    source, depth, mask, buffers = dome_with_two_lights(16)
    folder = tmp_path / "data" / "dome"
    write_pair_folder(folder, (source, source, depth, mask), buffers, roles=("normal", "light", "key"))
    path = tmp_path / "fill.toml"
    path.write_text(light_sweep_text('["law", "law,fill"]'))
    # Without fill_light.exr the trial with the fill is refused before anything runs.
    with pytest.raises(InvalidInputError, match=r"light term 'fill' needs fill_light\.exr in pair 'dome'"):
        ex.load(path)
    law_only = tmp_path / "law.toml"
    law_only.write_text(light_sweep_text('["law"]'))
    id_without = ex.load(law_only).trials[0].id
    invsss.write_image(folder / "fill_light.exr", np.asarray(buffers.fill_light, np.float32))
    law, fill = ex.load(path).trials
    # A folder that gained fill_light.exr keeps the ids of its trials without the fill.
    assert law.id == id_without and "fill_light" not in law.config["pairs"][0]
    assert "fill_light" in fill.config["pairs"][0] and "fill_light" in fill.buffer_roles
    # A pair given file by file names its fill_light too.
    files = tmp_path / "files.toml"
    names = {role: f"data/dome/{role}.{'png' if role == 'mask' else 'exr'}"
             for role in ("source", "target", "depth", "mask", "normal", "light", "key", "fill_light")}
    files.write_text(light_sweep_text('["law,fill"]').replace(
        '[data]\npairs = ["data/*/"]\n',
        "[data]\n[[data.files]]\nname = \"dome\"\n" + "".join(f'{k} = "{v}"\n' for k, v in names.items())))
    (trial,) = ex.load(files).trials
    assert trial.config["pairs"][0]["fill_light"] == names["fill_light"]
