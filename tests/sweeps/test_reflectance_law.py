"""A sweep with the ``law`` light term reads a pair folder's key.exr only for the
trials with the law, and keeps the ids of the trials without it."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightTerms
from tests.forward._lit_scenes import dome_with_two_lights, lit_target

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
def test_sweep_reads_the_key_only_for_trials_with_the_law(tmp_path):
    import invsss.sweeps as ex
    from tests.io._pair_files import light_sweep_text, write_pair_folder

    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.95, 0.85, 0.7]))
    folder = tmp_path / "data" / "dome"
    write_pair_folder(folder, (source, target, depth, mask), buffers)
    text = light_sweep_text('["incidence", "law"]')
    path = tmp_path / "law.toml"
    path.write_text(text)
    # Without key.exr the trial with the law is refused before anything runs.
    with pytest.raises(invsss.InvalidInputError, match=r"light term 'law' needs key\.exr in pair 'dome'"):
        ex.load(path)
    incidence_only = tmp_path / "incidence.toml"
    incidence_only.write_text(text.replace('["incidence", "law"]', '["incidence"]'))
    id_without_key = ex.load(incidence_only).trials[0].id
    invsss.write_image(folder / "key.exr", np.asarray(buffers.key, np.float32))
    experiment = ex.load(path)
    incidence, law = experiment.trials
    # A folder that gained key.exr keeps the ids of its trials without the law.
    assert incidence.id == id_without_key and "key" not in incidence.config["pairs"][0]
    assert "key" in law.config["pairs"][0]
    ex.run(path, tmp_path / "out")
    rows = {r["light_terms"]: r for r in ex.results(tmp_path / "out", frame=False)}
    assert all(r["status"] == "done" for r in rows.values())
    assert len(rows["law"]["stderr.law"]) == 3 and rows["incidence"]["param.law"] is None
    for w, err, true in zip(rows["law"]["param.law"], rows["law"]["stderr.law"], [0.95, 0.85, 0.7]):
        assert abs(w - true) < 4 * err
