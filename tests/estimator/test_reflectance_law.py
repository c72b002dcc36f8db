"""The estimator with the ``law`` light term: held albedos are kept and checked, a grey
target gets one albedo per source channel, an aligned fit moves the key light's part
with the source, and a missing key is named before fitting."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms
from tests.forward._lit_scenes import FIX, PROFILE, dome_with_two_lights, law_scene, lit_target

pytestmark = pytest.mark.usefixtures("float64")


@pytest.mark.slow
def test_a_held_albedo_is_kept_and_a_grey_target_fits_one_per_source_channel():
    source, depth, mask, buffers = dome_with_two_lights(32)
    truth = [0.95, 0.85, 0.7]
    target = lit_target(source, depth, mask, buffers, LightTerms(law=truth))
    held = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1,
                           light_terms={"law": truth}, light_buffers=buffers)
    assert held.light_terms["law"] == pytest.approx(truth) and held.light_terms["fixed"] == ["law"]
    assert held.light_terms["stderr"]["law"] is None
    assert float(held.params.sss_level) == pytest.approx(600.0, rel=0.02)
    # A grey (NIR-like) photograph of an RGB render: the law acts per source
    # channel, before the grey mix, so a grey target still gets three albedos.
    grey = target @ np.array([0.3, 0.5, 0.2])
    mixed = invsss.fit_pair(source, grey, depth, mask, profile=PROFILE, fix=FIX, n_starts=1,
                            light_terms="law", light_buffers=buffers)
    assert len(mixed.light_terms["law"]) == 3 and mixed.converged


@pytest.mark.slow
def test_an_aligned_fit_moves_the_key_with_the_source():
    # The photograph is misregistered by a fraction of a pixel; the aligned fit
    # resamples the source onto it, and the key light's part must move with it,
    # or the law would change the wrong pixels.
    source, depth, mask, buffers = dome_with_two_lights(40)
    truth = [0.95, 0.85, 0.7]
    target = lit_target(source, depth, mask, buffers, LightTerms(law=truth), noise=0.0)
    shifted = np.stack([ndimage.shift(target[..., k], (1.4, -0.8), order=5, mode="nearest") for k in range(3)], -1)
    # Two starts: from one, this dome has a second minimum at sss_level 746 (loss 2e-7),
    # with or without the warp.
    fit = invsss.fit_pair(source, shifted, depth, mask, profile=PROFILE, fix=FIX, n_starts=2, robust=None,
                          align="translation", light_terms="law", light_buffers=buffers)
    np.testing.assert_allclose(fit.alignment[0]["shift_px"], (1.4, -0.8), atol=0.1)
    assert fit.light_terms["law"] == pytest.approx(truth, abs=0.02)
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.05)


class TestBadInput:
    def setup_method(self):
        self.source, self.key, self.depth, self.mask, self.normal, self.light = law_scene()

    @pytest.mark.parametrize("terms, message", [
        ("law=1.2", r"light_terms\['law'\]: expected an albedo in \(0, 1\) or one per channel"),
        ({"law": "0.9/x"}, r"light_terms\['law'\]: expected an albedo"),
    ])
    def test_held_albedos_are_checked(self, terms, message):
        from invsss.estimator import FitOptions

        with pytest.raises(invsss.InvalidInputError, match=message):
            FitOptions(light_terms=terms)

    def test_a_fit_names_the_missing_key(self):
        with pytest.raises(invsss.InvalidInputError, match=r"^light_buffers\.key: the 'law' term needs this buffer"):
            invsss.fit_pair(self.source, self.source, self.depth, self.mask, light_terms="law",
                            light_buffers=LightBuffers(self.normal, self.light))

    @pytest.mark.slow
    def test_a_held_albedo_count_must_match_the_source(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\['law'\]: expected one albedo or one per "
                                                           r"source channel \(3\), got 2"):
            invsss.fit_pair(self.source, self.source, self.depth, self.mask, light_terms={"law": [0.9, 0.8]},
                            light_buffers=LightBuffers(self.normal, self.light, self.key))
