"""The dense references of experiments/gap_probe.py (issue 29, item 5): checked against
scipy's Gaussian filter and against each other where they must agree, so that what
the probe reports about the 7-tap passes and screen distance is about them."""

from __future__ import annotations

import importlib.util
import pathlib

import numpy as np
from scipy import ndimage

import invsss

_PATH = pathlib.Path(__file__).parents[1] / "experiments" / "gap_probe.py"
_SPEC = importlib.util.spec_from_file_location("gap_probe", _PATH)
gap_probe = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(gap_probe)

PARAMS = invsss.SSSParams(400.0, 0.0, 1.0, [1.0], [2.0])


def _image(size=32, seed=0):
    return np.random.default_rng(seed).uniform(0.0, 1.0, (size, size, 2))


def test_dense_screen_distance_on_a_flat_face_is_a_gaussian_filter():
    image = _image()
    depth = np.full(image.shape[:2], 500.0)
    mask = np.ones(image.shape[:2])
    layer = gap_probe.dense_layers(image, depth, mask, PARAMS, "screen", focal_px=400.0)[0]
    sigma = 400.0 / 500.0 * np.sqrt(2.0)  # s sqrt(v), px
    radius = int(np.ceil(3.0 * sigma))
    expected = np.stack([ndimage.gaussian_filter(image[..., c], sigma, mode="nearest", truncate=radius / sigma)
                         for c in range(2)], axis=-1)
    # scipy truncates to a disc-free square window too; both are normalised over it.
    np.testing.assert_allclose(layer, expected, atol=1e-12)


def test_surface_distance_equals_screen_distance_facing_the_camera_and_is_longer_when_tilted():
    image = _image(seed=1)
    mask = np.ones(image.shape[:2])
    mask[:4] = 0.0
    flat = np.full(image.shape[:2], 500.0)
    screen = gap_probe.dense_layers(image, flat, mask, PARAMS, "screen", focal_px=400.0)
    surface = gap_probe.dense_layers(image, flat, mask, PARAMS, "surface", focal_px=400.0)
    np.testing.assert_allclose(surface, screen, atol=1e-12)
    np.testing.assert_array_equal(surface[0][:4], image[:4])  # off the mask: unchanged
    # Tilted about the vertical axis: along the rows the surface distance grows, so
    # the blur there is narrower (closer to the image) than the screen distance's.
    tilted = 500.0 + 3.0 * np.arange(32.0)[None, :] + np.zeros((32, 1))
    narrow = gap_probe.dense_layers(image, tilted, mask, PARAMS, "surface", focal_px=400.0)[0]
    wide = gap_probe.dense_layers(image, tilted, mask, PARAMS, "screen", focal_px=400.0)[0]
    on = mask > 0
    assert np.abs(narrow - image)[on].mean() < 0.9 * np.abs(wide - image)[on].mean()
