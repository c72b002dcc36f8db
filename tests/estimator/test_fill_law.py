"""The estimator with the ``fill`` light term: it recovers the strength and gains over
the law alone, warns where the other lights are darker than any medium, finds nothing
where they are Lambertian; and the term's option needs the law and its buffer."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.estimator.options import check_light_terms
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_law
from invsss.validation import InvalidInputError
from tests.forward._lit_scenes import FIX, LAW_PARAMS, PROFILE, dome_with_two_lights, fill_scene, lit_target

pytestmark = pytest.mark.usefixtures("float64")


def test_fill_zero_is_the_identity_and_the_fill_needs_the_law_and_its_buffer():
    source, key, depth, mask, normal, light, fill_light = fill_scene(2)
    with_buffer = LightBuffers(normal, light, key, fill_light)
    assert LightTerms(law=0.9, fill=0.0).used == ("law",)
    assert LightTerms(law=0.9, law_strength=0.0, fill=0.5).used == ("fill",)
    np.testing.assert_array_equal(np.asarray(apply_law(source, mask, 0.9, with_buffer, 0.8, 0.0)),
                                  np.asarray(apply_law(source, mask, 0.9, LightBuffers(normal, light, key), 0.8)))
    # The fill has no albedo of its own.
    with pytest.raises(InvalidInputError, match="fill: the law on the other lights uses the law's albedo"):
        LightTerms(fill=0.5).check()
    with pytest.raises(InvalidInputError, match="'fill' applies the law's albedo"):
        check_light_terms("shift,fill")
    assert check_light_terms("law,fill=0.5") == (("law", "fill"), {"fill": 0.5})
    # Without its buffer: one line naming it.
    with pytest.raises(InvalidInputError, match="fill_light: the 'fill' term needs this buffer"):
        invsss.render(source, depth, mask, LAW_PARAMS, light_terms=LightTerms(law=0.9, fill=1.0),
                      light_buffers=LightBuffers(normal, light, key))
    # Checked as the other vectors are.
    with pytest.raises(InvalidInputError, match="fill_light: expected unit vectors"):
        invsss.render(source, depth, mask, LAW_PARAMS, light_terms=LightTerms(law=0.9, fill=1.0),
                      light_buffers=LightBuffers(normal, light, key, 2.0 * fill_light))


@pytest.mark.slow
def test_fit_recovers_the_fill_and_gains_over_the_law_alone():
    source, depth, mask, buffers = dome_with_two_lights()
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7], fill=1.0))
    kw = dict(profile=PROFILE, fix=FIX, n_starts=2, light_buffers=buffers)
    fit = invsss.fit_pair(source, target, depth, mask, light_terms="law,fill", **kw)
    assert fit.converged
    terms = fit.light_terms
    assert terms["stderr"]["fill"] is not None and abs(terms["fill"] - 1.0) < 4 * terms["stderr"]["fill"]
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.02)
    # Measured, not assumed: the fill's share of the fit, and the law alone fits worse.
    assert fit.psnr - terms["psnr_without"]["fill"] > 1.0
    key_only = invsss.fit_pair(source, target, depth, mask, light_terms="law", **kw)
    assert key_only.psnr < fit.psnr - 1.0
    # The fitted values render as fitted.
    assert float(fit.light_terms_params().fill) == pytest.approx(terms["fill"])
    assert not any("a gain that neither" in w for w in fit.warnings)


@pytest.mark.slow
def test_other_lights_darker_than_any_medium_are_warned_about():
    # The target's other lights lose light where every medium reflects more than
    # Lambert's law (a fill strength of -1.5): the fit finds that and says so.
    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7], fill=-1.5))
    fit = invsss.fit_pair(source, target, depth, mask, light_terms="law,fill", profile=PROFILE, fix=FIX,
                          n_starts=1, light_buffers=buffers)
    assert fit.light_terms["fill"] < -1.0
    assert any(w.startswith("light_terms.fill: at ") and "a gain that neither" in w for w in fit.warnings)


@pytest.mark.slow
def test_lambertian_other_lights_fit_as_the_law_alone():
    # The target's other lights are Lambertian (fill 0): the fill must find nothing,
    # and the fit with it must not end below the fit without it.
    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7]))
    kw = dict(profile=PROFILE, fix=FIX, n_starts=1, light_buffers=buffers)
    with_fill = invsss.fit_pair(source, target, depth, mask, light_terms="law,fill", **kw)
    key_only = invsss.fit_pair(source, target, depth, mask, light_terms="law", **kw)
    terms = with_fill.light_terms
    assert abs(terms["fill"]) < 4 * terms["stderr"]["fill"]
    assert with_fill.psnr > key_only.psnr - 0.05
    assert any("light_terms.fill: adds" in w for w in with_fill.warnings)
