"""A sweep with the light-aware terms reads normal.exr and light.exr from each pair
folder, fits the terms as fit_pair does, and refuses a term whose buffer is missing."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightTerms
from tests.forward._lit_scenes import lit_card

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
def test_sweep_fits_the_terms_from_pair_folder_buffers(tmp_path):
    """A sweep reads normal.exr and light.exr from the pair folder when a trial asks
    for light terms, reports kappa and gamma beside the parameters, recovers them as
    fit_pair does, and keeps the ids of trials without terms."""
    import invsss.sweeps as ex
    from invsss.sweeps.trials import trial_id
    from tests.io._pair_files import light_sweep_text, write_pair_folder

    source, depth, mask, buffers = lit_card(32)
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=LightTerms(shift=1.2, grazing=0.3),
                                      light_buffers=buffers))
    folder = tmp_path / "data" / "card"
    write_pair_folder(folder, (source, target, depth, mask), buffers)
    text = light_sweep_text('["", "shift,grazing"]')
    path = tmp_path / "lit.toml"
    path.write_text(text)
    experiment = ex.load(path)
    assert [t.options["light_terms"] for t in experiment.trials] == ["", "shift,grazing"]
    plain, lit = experiment.trials[0], experiment.trials[1]
    assert {"normal", "light"} <= set(plain.pairs[0])
    # Without terms the buffers and the option do not enter the id: the id of a
    # sweep made before either existed.
    older = {**plain.config, "pairs": [{k: v for k, v in plain.pairs[0].items() if k not in ("normal", "light")}]}
    older["options"] = {k: v for k, v in older["options"].items() if k != "light_terms"}
    assert plain.id == trial_id(older)
    assert "normal" in lit.config["pairs"][0]

    ex.run(path, tmp_path / "out")
    rows = {r["light_terms"]: r for r in ex.results(tmp_path / "out", frame=False)}
    assert all(r["status"] == "done" for r in rows.values())
    assert rows["shift,grazing"]["param.light_shift"] == pytest.approx(1.2, abs=0.05)
    assert rows["shift,grazing"]["param.grazing"] == pytest.approx(0.3, abs=0.01)
    assert rows["shift,grazing"]["stderr.light_shift"] > 0
    assert rows[""]["param.light_shift"] is None and rows[""]["param.grazing"] is None
    assert rows["shift,grazing"]["psnr"] > rows[""]["psnr"] + 3.0


def test_sweep_refuses_light_terms_without_the_buffer(tmp_path):
    import invsss.sweeps as ex
    from tests.io._pair_files import write_pair_folder

    source, depth, mask, _ = lit_card(16)
    write_pair_folder(tmp_path / "data" / "card", (source, source, depth, mask))
    path = tmp_path / "lit.toml"
    path.write_text('task = "fit"\n[data]\npairs = ["data/card/"]\n[base]\nlight_terms = ["shift"]\n')
    with pytest.raises(invsss.InvalidInputError, match=r"lit\.toml: trial 1 \(pair='card'\): light term 'shift' needs light\.exr "
                                                        r"in pair 'card'"):
        ex.load(path)
    path.write_text('task = "fit"\n[data]\npairs = ["data/card/"]\n[base]\nlight_terms = "tilt"\n')
    with pytest.raises(invsss.InvalidInputError, match=r"light_terms: unknown term"):
        ex.load(path)
