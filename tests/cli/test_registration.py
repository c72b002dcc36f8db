"""An aligned fit (``fit_pair(align=...)``) recovers the blur of a shifted target, and
its record, alignment included, is a valid params.json as the command line writes it."""

import json

import numpy as np
import pytest

import invsss
from invsss.io.params_file import ParamsFile
from tests.estimator._warped import shifted_pair

FIT = dict(profile={"weights": [1.0], "variances": [1.0]}, fix={"correction": 0.0, "maxdd": 1.0},
           n_starts=1, max_steps=60, robust=None)


@pytest.mark.slow
def test_fit_with_align_recovers_the_blur_of_a_shifted_target():
    source, target, depth, mask = shifted_pair()
    plain = invsss.fit_pair(source, target, depth, mask, **FIT)
    aligned = invsss.fit_pair(source, target, depth, mask, align="translation", **FIT)
    # Unaligned, the shift reads as a much wider blur; aligned, the truth comes back.
    assert abs(float(plain.params.sss_level) / 600.0 - 1.0) > 0.15
    assert float(aligned.params.sss_level) == pytest.approx(600.0, rel=0.02)
    np.testing.assert_allclose(aligned.alignment[0]["shift_px"], (1.4, -0.8), atol=0.05)
    assert aligned.psnr > plain.psnr + 10.0
    # The warp's own standard errors: positive, and far below the 0.05 px it is checked to.
    shift_err = aligned.alignment[0]["stderr"]["shift_px"]
    assert all(0.0 < e < 0.01 for e in shift_err)
    # The report goes into a valid params file.
    record = ParamsFile.model_validate(json.loads(json.dumps(aligned.to_dict())))
    assert record.alignment[0]["kind"] == "translation"
    assert json.loads(json.dumps(plain.to_dict()))["alignment"] is None
    # A fit on a resampled source says what that costs and what to do instead.
    said = [w for w in aligned.warnings if w.startswith("align: the source was resampled")]
    assert len(said) == 1 and "render the source again from the camera the warp implies" in said[0]
