"""The dense references of experiments/gap_probe.py (issue 29, item 5): checked against
scipy's Gaussian filter and against each other where they must agree, so that what
the probe reports about the 7-tap passes and screen distance is about them."""

from __future__ import annotations

import importlib.util

import numpy as np
from scipy import ndimage

import invsss
from tests import ROOT

_PATH = ROOT / "experiments" / "gap_probe.py"
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


def test_surface_areas_are_the_footprints_of_planes_and_of_a_crease():
    mask = np.ones((32, 32))
    flat = np.full((32, 32), 500.0)
    np.testing.assert_allclose(gap_probe.surface_areas(flat, mask, 400.0), (500.0 / 400.0) ** 2, rtol=1e-12)
    # Far from the camera (near-orthographic), a plane whose depth grows by 1.5 mm a
    # pixel of 1.25 mm covers sqrt(1.25^2 + 1.5^2) / 1.25 times the facing area, and a
    # crease of two such faces as much on its middle column.
    columns = np.abs(np.arange(32.0) - 16.0)[None, :] + np.zeros((32, 1))
    crease = 50000.0 + 1.5 * columns
    areas = gap_probe.surface_areas(crease, mask, 40000.0)
    expected = np.hypot(1.25, 1.5) * 1.25
    np.testing.assert_allclose(areas[4:28, 4:28], expected, rtol=2e-3)
    # An occluding edge counts at most ten times the facing area; off the mask nothing.
    step = flat.copy()
    step[:, 16:] += 200.0
    mask[:, :2] = 0.0
    areas = gap_probe.surface_areas(step, mask, 400.0)
    assert areas[:, 15].max() <= 10.0 * (500.0 / 400.0) ** 2 and np.all(areas[:, :2] == 0.0)


def test_surface_integral_is_the_normalised_blur_on_a_plane_facing_the_camera():
    image = _image(seed=2)
    mask = np.ones(image.shape[:2])
    flat = np.full(image.shape[:2], 500.0)
    surface = gap_probe.dense_layers(image, flat, mask, PARAMS, "surface", focal_px=400.0)
    integral = gap_probe.dense_layers(image, flat, mask, PARAMS, "integral", focal_px=400.0)
    np.testing.assert_allclose(integral, surface, rtol=1e-12, atol=1e-12)
    # Where the mask ends the surface goes on out of sight: uniform light stays uniform.
    mask[:, 20:] = 0.0
    uniform = gap_probe.dense_layers(np.ones((32, 32, 1)), flat, mask, PARAMS, "integral", focal_px=400.0)
    np.testing.assert_allclose(uniform[0], 1.0, rtol=1e-12)  # and off the mask it is left as it is


def test_surface_integral_keeps_uniform_light_on_a_tilted_plane_and_gathers_it_at_a_crease():
    image = np.ones((32, 32, 1))
    mask = np.ones((32, 32))
    params = invsss.SSSParams(40000.0, 0.0, 1.0, [1.0], [8.0])  # profile units: mm at this focal length
    columns = np.arange(32.0)[None, :] + np.zeros((32, 1))
    tilted = 50000.0 + 1.5 * columns
    integral = gap_probe.dense_layers(image, tilted, mask, params, "integral", focal_px=40000.0)[0, ..., 0]
    np.testing.assert_allclose(integral[10:22, 10:22], 1.0, rtol=2e-3)  # the profile integrates to 1
    # A Gaussian narrower than a pixel lands on the pixel itself: no gain from its tilt.
    narrow = invsss.SSSParams(40000.0, 0.0, 1.0, [1.0], [0.1])
    integral = gap_probe.dense_layers(image, tilted, mask, narrow, "integral", focal_px=40000.0)[0, ..., 0]
    np.testing.assert_allclose(integral[10:22, 10:22], 1.0, rtol=2e-3)
    crease = 50000.0 + 1.5 * np.abs(columns - 16.0)
    normalised = gap_probe.dense_layers(image, crease, mask, params, "surface", focal_px=40000.0)[0, ..., 0]
    integral = gap_probe.dense_layers(image, crease, mask, params, "integral", focal_px=40000.0)[0, ..., 0]
    np.testing.assert_allclose(normalised, 1.0, atol=1e-12)  # an average keeps uniform light anywhere
    # On the crease each face is a half-plane at its true distance: as on a plane.
    # Beside it the other face is nearer in space than along the surface, so more of
    # the profile lands there (the faces meet at 80 degrees).
    np.testing.assert_allclose(integral[10:22, 16], 1.0, rtol=2e-3)
    assert integral[10:22, [15, 17]].min() > 1.1 and integral[10:22, [15, 17]].max() < 1.3
    # A distance in space cannot tell a ridge from a valley: the medium's side does not enter.
    valley = gap_probe.dense_layers(image, 2 * 50000.0 - crease, mask, params, "integral",
                                    focal_px=40000.0)[0, ..., 0]
    np.testing.assert_allclose(valley[10:22, 12:21], integral[10:22, 12:21], rtol=2e-3)
