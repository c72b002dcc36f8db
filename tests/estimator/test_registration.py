"""Registration of the target onto the source (invsss.estimator.registration, fit_pair(align=...))."""

import json

import numpy as np
import pytest

import invsss
from invsss.estimator.registration import Warp, align_source, align_target, estimate_warp, match_photometry, warp_image
from invsss.validation import InvalidInputError
from tests.estimator._warped import inner_mask, photograph, shifted_pair, texture


@pytest.mark.slow
@pytest.mark.parametrize("kind, params", [
    ("translation", (1.3, -2.6)),
    ("similarity", (0.7, 1.1, float(np.radians(1.5)), float(np.log(1.02)))),
    ("affine", (-0.8, 0.4, 0.01, -0.015, 0.008, 0.012)),
])
def test_estimate_warp_recovers_a_known_warp(kind, params):
    reference = texture()
    mask = inner_mask()
    centre = tuple(float(v) for v in np.argwhere(mask > 0).mean(axis=0))
    truth = Warp(kind, params, centre)
    found = estimate_warp(photograph(reference, truth), reference, mask, kind)
    # Compare where the warp sends the mask's corners: a mapping error in pixels.
    corners = np.array([[14.0, 14.0], [14.0, 81.0], [81.0, 14.0], [81.0, 81.0]])
    assert np.abs(found.map_points(corners) - truth.map_points(corners)).max() < 0.03


def test_estimate_warp_ignores_gain_and_offset():
    reference = texture()
    mask = inner_mask()
    truth = Warp("translation", (2.2, 0.9), (47.5, 47.5))
    moving = 3.0 * photograph(reference, truth) + 0.2
    found = estimate_warp(moving, reference, mask, "translation")
    np.testing.assert_allclose(found.params, truth.params, atol=0.02)


@pytest.mark.parametrize("warp", [
    Warp("translation", (1.0, -2.0), (10.0, 12.0)),
    Warp("similarity", (0.5, 0.25, 0.02, -0.01), (40.0, 30.0)),
    Warp("affine", (0.5, 0.25, 0.01, 0.02, -0.03, 0.04), (40.0, 30.0)),
])
def test_warp_record_round_trips_through_json(warp):
    back = Warp.from_dict(json.loads(json.dumps(warp.to_dict())))
    assert back.kind == warp.kind
    np.testing.assert_allclose(back.params, warp.params, atol=1e-12)
    np.testing.assert_allclose(back.centre, warp.centre)


@pytest.mark.parametrize("warp", [
    Warp("translation", (1.0, -2.0), (10.0, 12.0)),
    Warp("similarity", (0.5, 0.25, 0.02, -0.01), (40.0, 30.0)),
    Warp("affine", (0.5, 0.25, 0.01, 0.02, -0.03, 0.04), (40.0, 30.0)),
])
def test_recentred_warp_is_the_same_map_about_a_new_centre(warp):
    moved = warp.recentred((63.5, 31.5))
    points = np.random.default_rng(0).uniform(-20.0, 100.0, (50, 2))
    np.testing.assert_allclose(moved.map_points(points), warp.map_points(points), atol=1e-10)
    np.testing.assert_allclose(moved.params[2:], warp.params[2:])
    assert moved.centre == (63.5, 31.5)
    # The new centre moves by the recentred shift alone.
    np.testing.assert_allclose(moved.map_points(np.array([[63.5, 31.5]]))[0], np.add((63.5, 31.5), moved.params[:2]))


def test_align_source_puts_the_source_on_the_target_grid():
    reference = texture(64)
    warp = Warp("similarity", (1.5, -0.5, float(np.radians(2.0)), float(np.log(1.01))), (31.5, 31.5))
    photo = photograph(reference, warp)
    depth = np.full((64, 64), 500.0)
    depth[:, :4] = 0.0  # a renderer's background: filled before resampling
    moved, moved_depth, kept = align_source(reference, depth, np.ones((64, 64)), warp, (64, 64))
    inner = kept > 0.999
    inner[:6], inner[-6:], inner[:, :6], inner[:, -6:] = False, False, False, False
    assert inner.sum() > 2000
    # The source resampled onto the target's grid is the photograph (both of one smooth image).
    assert np.abs(moved - photo)[inner].max() < 2e-3
    np.testing.assert_allclose(moved_depth, 500.0, rtol=1e-12)
    # Target pixels that come from outside the source's frame are not skin.
    corners = warp.inverse_map_points(np.array([[0.0, 0.0], [63.0, 63.0]]))
    assert (corners < 0).any() or (corners > 63).any()
    assert kept[0, 0] == 0.0 or kept[63, 63] == 0.0


def test_align_target_undoes_the_warp_and_drops_pixels_from_outside():
    reference = texture(64)
    warp = Warp("translation", (3.0, 0.0), (31.5, 31.5))
    moving = photograph(reference, warp)
    aligned, kept = align_target(moving, np.ones((64, 64)), warp)
    # Integer shift: exact where the warped position lies inside the frame.
    np.testing.assert_allclose(aligned[:61], reference[:61], atol=1e-9)
    assert kept[61:].sum() == 0 and kept[:61].all()


def test_match_photometry_finds_a_channel_mix():
    rng = np.random.default_rng(1)
    rgb = rng.uniform(size=(16, 16, 3))
    grey = (rgb @ np.array([0.5, 0.3, 0.2]) * 2.0 + 0.1)[..., None]
    np.testing.assert_allclose(match_photometry(rgb, grey, np.ones((16, 16))), grey, atol=1e-10)


def test_align_rejects_an_unknown_kind():
    source, target, depth, mask = shifted_pair()
    with pytest.raises(InvalidInputError, match=r"^align: expected one of none, translation, similarity, affine"):
        invsss.fit_pair(source, target, depth, mask, align="homography")


def test_warp_image_marks_samples_outside_the_frame():
    image = np.ones((8, 8, 1))
    _, valid = warp_image(image, Warp("translation", (0.0, -2.5), (3.5, 3.5)))
    assert not valid[:, :3].any() and valid[:, 3:].all()
