"""The bundled synthetic pairs in data_synthetic/ are what their truth.json says.

Each scene's target must be the recorded forward model of its source plus noise of
the recorded size, so an estimator that recovers truth.json from these files is
recovering real, known parameters (made by experiments/make_synthetic.py).
"""

import json

import numpy as np
import pytest

import invsss
from invsss.io import PARAMS_KEYS, read_depth, read_image, read_mask
from tests import ROOT

DATA = ROOT / "data_synthetic"
SCENES = sorted(p.name for p in DATA.iterdir() if (p / "truth.json").is_file())
FACE_SCENES = [s for s in SCENES if s != "flat_card"]


def load(name):
    folder = DATA / name
    truth = json.loads((folder / "truth.json").read_text())
    return (
        read_image(folder / "source.exr"),
        read_image(folder / "target.exr"),
        read_depth(folder / "depth.exr"),
        read_mask(folder / "mask.png"),
        truth,
    )


def noise_free_target(source, depth, mask, truth, **changes):
    """The recorded formula: gain * (channels_mix . render(...)) + offset."""
    params = invsss.SSSParams.from_dict({**{k: truth[k] for k in PARAMS_KEYS}, **changes})
    out = invsss.render(
        source, depth, mask, params, truth["model"], tap_weights=truth["tap_weights"]
    )
    out = np.asarray(out, np.float64)
    if truth["channels_mix"] is not None:
        out = out @ np.asarray(truth["channels_mix"])[:, None]
    return np.asarray(truth["gain"]) * out + np.asarray(truth["offset"])


def masked_rms(a, b, mask):
    return float(np.sqrt(np.mean((a - b)[mask > 0.5] ** 2)))


def test_bundle_has_the_documented_scenes():
    assert {"fran_front", "fran_turned", "flat_card"} <= set(SCENES)
    readme = (DATA / "README.md").read_text()
    for name in SCENES:
        assert f"`{name}`" in readme


@pytest.mark.parametrize("name", SCENES)
def test_scene_files_have_consistent_shapes_and_ranges(name):
    source, target, depth, mask, truth = load(name)
    h, w = truth["scene"]["image_size"]
    assert source.shape == (h, w, 3)
    assert target.shape == (h, w, 1 if truth["channels_mix"] is not None else 3)
    assert depth.shape == mask.shape == (h, w)
    assert np.all(np.isfinite(source)) and source.min() >= 0.0
    assert np.all(np.isfinite(target))
    # read_depth keeps a renderer's 0/inf background, so the skin is checked here;
    # the camera sits 400-600 mm away.
    skin = mask > 0.5
    assert np.all(np.isfinite(depth[skin])) and depth[skin].min() > 0.0
    assert 400.0 <= np.median(depth[skin]) <= 600.0
    assert set(np.unique(mask)) == {0.0, 1.0}
    assert 0.2 < skin.mean() < 0.9
    assert truth["sss_level"] == truth["focal_px"]


@pytest.mark.parametrize("name", SCENES)
def test_target_is_the_model_plus_the_recorded_noise(name):
    source, target, depth, mask, truth = load(name)
    residual = target - noise_free_target(source, depth, mask, truth)
    sigma = truth["noise_sigma"]
    assert 0.8 * sigma < residual.std() < 1.2 * sigma
    assert abs(residual.mean()) < 5 * sigma / np.sqrt(residual.size)
    # On skin, where the parameters act: with over 20000 pixels the sample std is
    # within 1 % of sigma, so 5 % catches a wrong parameter (sss_level off by 10 %
    # gives 1.1 to 1.3 sigma here) but not chance.
    on_skin = residual[mask > 0.5]
    assert on_skin.size > 20000
    assert 0.95 * sigma < on_skin.std() < 1.05 * sigma
    # The scattering must stand well above the noise, or there is nothing to fit:
    # leaving it out (the source through the same gain and mix) misses by many sigma.
    unscattered = np.asarray(truth["gain"]) * (
        source @ np.asarray(truth["channels_mix"])[:, None]
        if truth["channels_mix"] is not None
        else source
    ) + np.asarray(truth["offset"])
    assert masked_rms(unscattered, target, mask) > 5 * sigma


@pytest.mark.parametrize("name", SCENES)
def test_recorded_slope_fractions_and_undetermined_parameters(name):
    source, _, depth, mask, truth = load(name)
    dy, dx = np.gradient(depth)
    skin = mask > 0.5
    fractions = truth["scene"]["fraction_of_mask_with_slope_above_maxdd"]
    assert fractions["x"] == pytest.approx(np.mean(np.abs(dx[skin]) > truth["maxdd"]), abs=1e-6)
    assert fractions["y"] == pytest.approx(np.mean(np.abs(dy[skin]) > truth["maxdd"]), abs=1e-6)
    clean = noise_free_target(source, depth, mask, truth)
    no_correction = noise_free_target(source, depth, mask, truth, correction=0.0)
    if "correction" in truth["undetermined"]:
        # Flat depth: the correction term is identically zero.
        assert np.all(depth == depth[0, 0])
        np.testing.assert_allclose(no_correction, clean, atol=1e-6)
    else:
        assert 0.1 < min(fractions["x"], fractions["y"])
        assert max(fractions["x"], fractions["y"]) < 0.9
        assert masked_rms(no_correction, clean, mask) > truth["noise_sigma"]


@pytest.mark.parametrize("name", SCENES)
def test_normalised_weights_are_the_fit_form_of_the_weights(name):
    # weights_normalised is what a fit's params.json holds: per-channel sums of 1,
    # shape (K,) for a one-channel target and (K, 3) for an RGB one. The sog model
    # divides by the weights' sum, so it must render the very same target.
    source, target, depth, mask, truth = load(name)
    weights = np.asarray(truth["weights"], np.float64)
    normalised = np.asarray(truth["weights_normalised"], np.float64)
    k = len(truth["variances"])
    assert normalised.shape == ((k,) if target.shape[-1] == 1 else (k, target.shape[-1]))
    np.testing.assert_allclose(normalised.sum(axis=0), 1.0, atol=1e-5)
    expected = weights / weights.sum()
    if normalised.ndim == 2:
        expected = np.repeat(expected[:, None], normalised.shape[1], axis=1)
    np.testing.assert_allclose(normalised, expected, atol=1e-6)
    np.testing.assert_allclose(
        noise_free_target(source, depth, mask, truth, weights=normalised),
        noise_free_target(source, depth, mask, truth),
        rtol=1e-5, atol=1e-6,
    )


@pytest.mark.parametrize("name", SCENES)
def test_undetermined_weights_are_those_of_coinciding_gaussians(name):
    # A fit cannot separate two Gaussians whose layers differ by a blur below
    # COINCIDENT_PX pixel at the largest stretch on the mask; truth.json must list
    # their weights (every channel for an RGB target), each with a reason. It may
    # list more (a weight whose standard error is too large in one scene).
    from invsss.estimator.uncertainty import COINCIDENT_PX
    from invsss.forward.stretch import stretch_factors

    _, target, depth, mask, truth = load(name)
    assert set(truth["undetermined_why"]) == set(truth["undetermined"])
    assert all(isinstance(v, str) and v for v in truth["undetermined_why"].values())
    s_x, s_y = stretch_factors(depth, truth["sss_level"], truth["correction"], truth["maxdd"])
    skin = mask > 0.5
    s_max = float(max(np.max(np.asarray(s_x)[skin]), np.max(np.asarray(s_y)[skin])))
    v = np.asarray(truth["variances"])
    order = np.argsort(v)
    coinciding = set()
    for a, b in zip(order[:-1], order[1:]):
        if s_max * np.sqrt(v[b] - v[a]) < COINCIDENT_PX:
            coinciding |= {int(a), int(b)}
    channels = target.shape[-1]
    expected = {
        f"weights[{i}]" if channels == 1 else f"weights[{i},{c}]"
        for i in coinciding
        for c in range(channels)
    }
    listed = {e for e in truth["undetermined"] if e.startswith("weights")}
    assert coinciding and expected <= listed
