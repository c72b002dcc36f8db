"""Fitting the ``transmission`` term (issue 48): a model-made back-lit pair gives its tint
and thickness scale back within 5 %, and a pair without transmitted light keeps the
plain fit (the term nests)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms
from invsss.validation import InvalidInputError
from tests.forward._backlit_scenes import backlit_dome

TRUTH = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
PROFILE = {"weights": [0.5, 0.5], "variances": [0.5, 2.0]}
FIX = {"correction": 0.0, "maxdd": 1.0}


def _fit(source, target, depth, mask, buffers, **keywords):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, light_terms="transmission",
                               light_buffers=buffers, **keywords)


@pytest.mark.slow
def test_backlit_pair_gives_its_tint_and_thickness_scale_back():
    source, depth, mask, buffers = backlit_dome(size=40)
    terms = LightTerms(transmission=0.8, thickness_scale=0.1)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH, light_terms=terms, light_buffers=buffers))
    target = target + np.random.default_rng(1).normal(0.0, 0.0005, target.shape)
    fit = _fit(source, target, depth, mask, buffers)
    record = fit.light_terms
    assert record["transmission"][0] == pytest.approx(0.8, rel=0.05)
    assert record["thickness_scale"] == pytest.approx(0.1, rel=0.05)
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.05)
    # The plain fit cannot explain the light that crossed the dome: the term buys much.
    assert fit.psnr > record["psnr_plain"] + 10.0
    assert record["stderr"]["transmission"][0] < 0.05


@pytest.mark.slow
def test_without_transmitted_light_the_tint_stays_near_zero_and_the_fit_is_the_plain_one():
    source, depth, mask, buffers = backlit_dome(size=40)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH))
    target = target + np.random.default_rng(2).normal(0.0, 0.0005, target.shape)
    fit = _fit(source, target, depth, mask, buffers)
    record = fit.light_terms
    assert fit.psnr >= record["psnr_plain"] - 1e-6
    if not record.get("fallback"):
        tint, err = record["transmission"][0], record["stderr"]["transmission"][0]
        assert abs(tint) < max(3.0 * (err or 0.0), 0.01)
        assert any("light_terms.transmission" in w and "does not describe this pair" in w for w in fit.warnings)


def test_missing_or_bad_transmission_buffers_are_refused_before_any_fit():
    source, depth, mask, buffers = backlit_dome(size=16)
    target = np.asarray(invsss.render(source, depth, mask, TRUTH))
    no_irradiance = LightBuffers(buffers.normal, buffers.light, thickness=buffers.thickness)
    with pytest.raises(InvalidInputError, match="light_buffers.key_irradiance: the 'transmission' term needs"):
        _fit(source, target, depth, mask, no_irradiance)
    thickness = np.array(buffers.thickness)
    thickness[8, 8] = -2.0
    bad = LightBuffers(buffers.normal, buffers.light, thickness=thickness, key_irradiance=buffers.key_irradiance)
    with pytest.raises(InvalidInputError, match="thickness: expected a thickness >= 0 mm"):
        _fit(source, target, depth, mask, bad)


def test_a_thickness_scale_that_flattens_the_transmittance_is_named():
    from invsss.estimator.stages.light_terms import thickness_unused

    source, depth, mask, buffers = backlit_dome(size=16)
    pair = invsss.ImagePair(source, source, depth, mask, thickness=buffers.thickness)
    median = float(np.median(np.asarray(buffers.thickness)[(mask > 0) & (np.asarray(buffers.thickness) > 0.5)]))
    for scale, words in ((1e-5 / median, "passes the same light through every thickness"),
                         (1e4 / median, "only where the key light meets the surface itself")):
        (message,) = thickness_unused([pair], {"transmission": [0.4], "thickness_scale": scale})
        assert message.startswith("light_terms.thickness_scale: ") and words in message
    assert thickness_unused([pair], {"transmission": [0.4], "thickness_scale": 1.0 / median}) == []
    assert thickness_unused([pair], {"transmission": [0.0], "thickness_scale": 1e-9}) == []
