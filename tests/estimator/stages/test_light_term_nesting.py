"""Light terms that can only make a fit better (issue 29): every term has a value
that is the identity, a fit with terms starts from the plain fit, the law's gain is
bounded on the buffers renderers write, and the fit warns when a term does not help,
ends at the edge of its range, or when a handful of pixels carry the loss."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import invsss
from invsss.estimator.stages import light_terms as light_terms_stage
from invsss.forward.light_terms import LAW_TRUST, LightBuffers, LightTerms, law_excess, reflectance_law

from tests.forward._lit_scenes import FIX, PROFILE, TRUTH, dome_with_two_lights, lit_target


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _fit(source, target, depth, mask, **options):
    return invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2, **options)


# ---------------------------------------------------------------- the identity


@pytest.mark.slow
def test_every_term_has_an_identity():
    source, depth, mask, buffers = dome_with_two_lights(24)
    params = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    plain = np.asarray(invsss.render(source, depth, mask, params))
    identity = LightTerms(shift=0.0, grazing=0.0, incidence=0.0, law=[0.3, 0.6, 0.9], law_strength=0.0)
    assert identity.used == ()
    out = invsss.render(source, depth, mask, params, light_terms=identity, light_buffers=buffers)
    np.testing.assert_array_equal(np.asarray(out), plain)
    # Strength 1 is the law; a half strength is half its change of the source.
    full = invsss.apply_law(source, mask, 0.8, buffers, 1.0)
    half = invsss.apply_law(source, mask, 0.8, buffers, 0.5)
    np.testing.assert_allclose(np.asarray(half) - source, 0.5 * (np.asarray(full) - source), rtol=1e-6, atol=1e-7)
    assert float(np.max(np.abs(np.asarray(full) - source))) > 0.01


# ------------------------------------------------------ buffers as renderers write them


def _awkward_buffers(size=32, seed=4):
    """Normals and light directions of every kind a renderer's buffers hold: facing
    the camera, facing away from it (a smoothed low-poly normal, a normal map), at
    the silhouette (n_z = 0), lit from behind (n . l < 0) and at grazing incidence."""
    rng = np.random.default_rng(seed)
    normal = _unit(rng.normal(size=(size, size, 3)))
    light = _unit(rng.normal(size=(size, size, 3)) + [0.0, 0.0, 0.5])
    normal[0, :4] = [[0.6, 0.0, -0.8], [0.0, -0.3, -0.95], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    light[0, :4] = [[-0.6, 0.0, 0.8], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    return normal, light


@pytest.mark.slow
@pytest.mark.parametrize("albedo", [1e-9, 0.5, 0.9, 0.99, 1.0 - 1e-9])
def test_the_law_gain_is_bounded_and_one_where_the_buffers_cannot_resolve_it(albedo):
    normal, light = _awkward_buffers()
    with jax.enable_x64(True):
        gain = np.asarray(reflectance_law(normal, light, albedo))[..., 0]
    assert np.all(np.isfinite(gain))
    assert gain.max() <= 1.0 + 1.0 / LAW_TRUST and gain.min() >= 0.7
    n_z = normal[..., 2]
    n_l = np.sum(normal * light, axis=-1)
    away = (n_z <= 0.0) | (n_l <= 0.0)
    assert away.sum() > 100  # every kind is there, many times
    np.testing.assert_array_equal(gain[away], 1.0)
    # Where both cosines reach LAW_TRUST the law is not faded at all: Hapke's H.
    root = np.sqrt(max(1.0 - albedo, 1e-12))

    def h(x):
        return (1 + 2 * x) / (1 + 2 * x * root)

    trusted = (n_z >= LAW_TRUST) & (n_l >= LAW_TRUST)
    mu, mu0 = n_z[trusted], n_l[trusted]
    np.testing.assert_allclose(gain[trusted], h(mu) * h(mu0) / (mu + mu0) / (h(1.0) ** 2 / 2.0), rtol=1e-9)


@pytest.mark.slow
def test_nan_and_zero_buffers_off_the_mask_change_nothing_there():
    source, depth, mask, buffers = dome_with_two_lights(24)
    off = mask == 0
    normal, light, key = (np.array(b) for b in (buffers.normal, buffers.light, buffers.key))
    normal[off] = np.nan
    light[off] = 0.0
    key[off] = np.nan
    terms = LightTerms(shift=0.7, grazing=0.2, incidence=0.1, law=0.9)
    params = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    out = np.asarray(invsss.render(source, depth, mask, params, light_terms=terms,
                                   light_buffers=LightBuffers(normal, light, key)))
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out[off], source[off], rtol=1e-6)
    clean = np.asarray(invsss.render(source, depth, mask, params, light_terms=terms, light_buffers=buffers))
    np.testing.assert_allclose(out, clean, rtol=1e-6, atol=1e-7)
    # On the mask a NaN is still refused, naming the buffer.
    key[~off] = np.nan
    with pytest.raises(invsss.InvalidInputError, match="light_buffers.key: NaN or infinite values on the mask"):
        invsss.render(source, depth, mask, params, light_terms=terms, light_buffers=LightBuffers(normal, light, key))


# ------------------------------------------------------------------ the fits


@pytest.mark.slow
def test_the_law_on_a_lambertian_target_fits_as_the_plain_model():
    source, depth, mask, buffers = dome_with_two_lights()
    target = lit_target(source, depth, mask, buffers, None)  # the renderer's Lambert: the law is wrong
    plain = _fit(source, target, depth, mask)
    law = _fit(source, target, depth, mask, light_terms="law", light_buffers=buffers)
    assert abs(law.psnr - plain.psnr) <= 0.05
    record = law.light_terms
    assert record["psnr_plain"] == pytest.approx(plain.psnr, abs=1e-9)
    assert abs(record["law_strength"]) < 0.1
    # The law adds nothing here, and the fit says so (or returns the plain fit,
    # where the fit with the law ended a rounding below it).
    assert any(w.startswith("light_terms.law: adds") or "below the plain fit" in w for w in law.warnings)
    assert not any("residual:" in w for w in (*law.warnings, *plain.warnings))


def _starts(fit):
    return {label.split(",")[0] for label, _, _ in fit.stages if label.startswith("start")}


@pytest.mark.slow
def test_a_term_fit_from_the_plain_fit_finds_the_basin_the_terms_lead_to():
    source, depth, mask, buffers = dome_with_two_lights()
    target = lit_target(source, depth, mask, buffers, LightTerms(law=0.9))
    fits = {how: _fit(source, target, depth, mask, light_terms="law", light_buffers=buffers, term_starts=how)
            for how in ("scan", "plain")}
    # The plain fit's estimate and the scan's two starts (n_starts=2); or the
    # estimate, then the one scanned point that was below where its solve ended.
    assert _starts(fits["scan"]) == {"start 1", "start 2", "start 3"}
    assert _starts(fits["plain"]) == {"start 1", "start 2"}
    # From the plain fit's estimate alone the fit with the law ended at a wider
    # blur (sss_level 746, 47 standard errors off); both find the dome's.
    for fit in fits.values():
        assert fit.psnr > fit.light_terms["psnr_plain"] + 3.0
        assert np.allclose(fit.light_terms["law"], 0.9, atol=0.01)
        assert abs(float(fit.params.sss_level) - TRUTH.sss_level) < 3.0 * fit.stderr["sss_level"]


@pytest.mark.slow
def test_a_term_fit_from_the_plain_fit_solves_once_where_its_basin_is_the_best():
    source, depth, mask, buffers = dome_with_two_lights()
    target = lit_target(source, depth, mask, buffers, LightTerms(shift=0.5))
    fit = _fit(source, target, depth, mask, light_terms="shift", light_buffers=buffers, term_starts="plain")
    assert _starts(fit) == {"start 1"}
    assert fit.psnr > fit.light_terms["psnr_plain"] + 3.0
    assert abs(float(fit.params.sss_level) - TRUTH.sss_level) < 3.0 * fit.stderr["sss_level"]


@pytest.mark.slow
def test_normals_facing_away_on_one_percent_of_the_mask_do_not_light_up_the_prediction():
    source, depth, mask, buffers = dome_with_two_lights()
    target = lit_target(source, depth, mask, buffers, LightTerms(law=0.9))
    # The buffers the fit gets are a renderer's: 1 % of the skin's normals face
    # away from the camera (smoothed low-poly normals, a normal map's error).
    rng = np.random.default_rng(7)
    on = np.flatnonzero(mask.ravel() > 0)
    wrong = rng.choice(on, size=int(0.01 * on.size), replace=False)
    normal = np.array(buffers.normal).reshape(-1, 3)
    normal[wrong] = _unit(normal[wrong] * [1.0, 1.0, -1.0] + [0.0, 0.0, -0.1])
    faulty = LightBuffers(normal.reshape(buffers.normal.shape), buffers.light, buffers.key)
    fit = _fit(source, target, depth, mask, light_terms="law", light_buffers=faulty)
    assert float(np.max(fit.fitted)) <= float(np.max(target))
    assert fit.psnr > fit.light_terms["psnr_plain"] + 3.0  # the law still does its work elsewhere


@pytest.mark.slow
def test_a_few_wrong_pixels_carrying_the_loss_are_warned_about():
    source, depth, mask, buffers = dome_with_two_lights()
    target = lit_target(source, depth, mask, buffers, None)
    rows, cols = np.nonzero(mask > 0)
    target[rows[::400], cols[::400]] += 2.0  # three hot pixels of a sensor
    fit = _fit(source, target, depth, mask)
    found = [w for w in fit.warnings if w.startswith("residual:")]
    assert len(found) == 1
    assert any(f"the worst at row {r}, column {c};" in found[0] for r, c in zip(rows[::400], cols[::400]))


def test_terms_at_the_edge_of_their_range_are_warned_about():
    quiet = {"law": [0.93], "law_strength": 0.98, "grazing": 0.2, "stderr": {"law_strength": 0.05}, "fixed": []}
    assert light_terms_stage.term_bounds(quiet) == []
    at_edge = dict(quiet, law=[0.99993])
    assert "light_terms.law: the albedo ended at 0.99993" in light_terms_stage.term_bounds(at_edge)[0]
    # A strength outside [0, 1] is judged against the buffers (unlike_any_medium), not here.
    assert light_terms_stage.term_bounds(dict(quiet, law_strength=1.4)) == []
    darkened = dict(quiet, grazing=-0.995)
    assert "light_terms.grazing: -0.995 is at its bound -1" in light_terms_stage.term_bounds(darkened)[0]
    held = dict(at_edge, fixed=["law"])
    assert light_terms_stage.term_bounds(held) == []


@pytest.mark.parametrize("albedo, strength, beyond", [(0.9, 1.6, False), (0.3, 3.0, True), (0.95, -1.0, True),
                                                       (0.6, 0.5, False)])
def test_law_excess_is_the_distance_to_every_albedos_gain(albedo, strength, beyond):
    # The definition, brute force: the gains of the law at 201 albedos and Lambert's 1.
    _, _, _, buffers = dome_with_two_lights()
    normal, light = np.asarray(buffers.normal), np.asarray(buffers.light)
    grid = np.stack([np.asarray(reflectance_law(normal, light, w))[..., 0] for w in np.linspace(0.0, 1.0, 201)])
    low, high = np.minimum(grid.min(0), 1.0), np.maximum(grid.max(0), 1.0)
    blend = 1.0 + strength * (np.asarray(reflectance_law(normal, light, albedo))[..., 0] - 1.0)
    expected = np.maximum(np.maximum(low - blend, blend - high), 0.0)
    got = np.asarray(law_excess(normal, light, albedo, strength))[..., 0]
    np.testing.assert_allclose(got, expected, atol=1e-5)
    # A blend of two physical laws is physical; beyond them it may or may not be
    # (1.6 at w = 0.9 is a gain that lower albedos give on every pixel here).
    assert np.any(got > 0.01) == beyond


def test_a_strength_beyond_every_medium_is_warned_about():
    source, _, mask, b = dome_with_two_lights()
    pair = invsss.ImagePair(source, source, np.ones_like(mask), mask, normal=b.normal, light=b.light,
                            key=b.key, fill_light=b.fill_light)
    quiet = {"law": [0.9, 0.8, 0.7], "law_strength": 1.0, "fill": 0.5,
             "stderr": {"law_strength": 0.05, "fill": 0.05}, "fixed": []}

    def found(**changes):
        return light_terms_stage.unlike_any_medium([pair], {**quiet, **changes})

    assert found() == []
    # What the procedural heads fit (docs/model.md, section 8): outside [0, 1] and
    # still a gain that a lower albedo gives, so not a warning.
    assert found(law=[0.977], law_strength=1.6, stderr={"law_strength": 0.26, "fill": 0.05}) == []
    darker = found(law_strength=-1.0)
    assert len(darker) == 1 and darker[0].startswith("light_terms.law_strength: at -1 ± 0.05 the blend gives")
    assert "of the key light's part a gain that neither" in darker[0]
    assert len(found(law=[0.3], law_strength=3.0)) == 1
    (fill,) = found(fill=-1.5)
    assert fill.startswith("light_terms.fill: at -1.5 ± 0.05") and "the other lights' part" in fill
    # Two standard errors from [0, 1] the data allow a physical blend; a held strength is the user's.
    assert found(law_strength=-1.0, stderr={"law_strength": 0.6, "fill": 0.05}) == []
    assert found(law_strength=-1.0, fixed=["law_strength"]) == []


@pytest.mark.slow
def test_a_term_fit_below_the_plain_fit_falls_back_to_it(monkeypatch):
    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=0.9))
    # Make the plain fit look better than any fit with the terms can be: the
    # comparison, not the solve, decides what is returned.
    original = light_terms_stage.against_plain

    def plain_scores_higher(problem, path, result, plain):
        return original(problem, path, result, dataclasses.replace(plain, psnr=result.psnr + 1.0))

    monkeypatch.setattr(light_terms_stage, "against_plain", plain_scores_higher)
    fit = _fit(source, target, depth, mask, light_terms="shift,law", light_buffers=buffers)
    record = fit.light_terms
    assert record["fallback"] is True and record["law_strength"] == 0.0 and record["shift"] == 0.0
    assert fit.light_terms_params().used == ()
    assert any("below the plain fit" in w for w in fit.warnings)
    plain = _fit(source, target, depth, mask)
    np.testing.assert_array_equal(np.asarray(fit.fitted), np.asarray(plain.fitted))


def test_a_residual_at_the_level_of_rounding_points_at_no_pixel():
    from invsss.estimator.summary import CONCENTRATED_FLOOR_DB, concentrated_residual

    rng = np.random.default_rng(2)
    target = rng.uniform(0.2, 1.0, (40, 50, 1))
    mask = np.ones((40, 50))
    spike = np.zeros_like(target)
    spike[7, 9] = 1.0  # one pixel carries all of the residual
    # 65 dB below the peak: rounding, nothing to point at (a target that was the source).
    tiny = 10.0 ** (-(CONCENTRATED_FLOOR_DB + 5.0) / 20.0) * np.sqrt(target.size)
    assert concentrated_residual([target + tiny * spike], [target], [mask], True) == []
    # The same pattern 55 dB below it is a pixel to look at.
    large = tiny * 10.0 ** (10.0 / 20.0)
    found = concentrated_residual([target + large * spike], [target], [mask], True)
    assert len(found) == 1 and "the worst at row 7, column 9;" in found[0]
