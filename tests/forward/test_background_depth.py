"""Renderer-style depth: 0 or +inf off the mask is accepted by render.

The reference in each test is the same pair with a finite background that
continues the surface flat, which is what the background must act like; the
depth is built flat near the mask edge so that this reference is unambiguous
(tests/forward/_background_scene.py). The fit, the twin and the files are tested in
the folders of their layers (test_background_depth.py in each).
"""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.forward.pair import fill_background_depth
from invsss.validation import InvalidInputError
from tests.forward._background_scene import PARAMS, scene, with_background


@pytest.mark.parametrize("background", [0.0, np.inf])
def test_render_with_renderer_background_equals_finite_background(background):
    image, depth, mask = scene()
    expected = np.asarray(invsss.render(image, depth, mask, PARAMS))
    got = np.asarray(invsss.render(image, with_background(depth, mask, background), mask, PARAMS))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got[mask > 0], expected[mask > 0], rtol=1e-6)


def test_fill_copies_the_nearest_valid_depth():
    depth = np.array([[np.inf, 510.0, 520.0], [0.0, 500.0, np.nan], [-1.0, 0.0, 0.0]])
    filled = fill_background_depth(depth)
    np.testing.assert_array_equal(
        filled, [[510.0, 510.0, 520.0], [500.0, 500.0, 500.0], [500.0, 500.0, 500.0]]
    )
    finite = np.full((3, 3), 400.0)
    assert fill_background_depth(finite) is finite  # nothing to do: no copy
    with pytest.raises(InvalidInputError, match="no pixel"):
        fill_background_depth(np.zeros((3, 3)))


def test_a_soft_rim_may_lack_depth_where_the_background_does():
    # An anti-aliased mask reaches into pixels whose depth saw the background (0):
    # filled like the background, not refused (the rim used to be "293 masked pixels").
    image, depth, mask = scene()
    soft = mask.copy()
    soft[2, 4:20] = soft[17, 4:20] = 0.5  # a rim above and below the hard mask
    renderer = with_background(depth, mask, 0.0)  # no depth on the rim
    got = np.asarray(invsss.render(image, renderer, soft, PARAMS))
    expected = np.asarray(invsss.render(image, fill_background_depth(renderer), soft, PARAMS))
    np.testing.assert_array_equal(got, expected)
    assert np.all(np.isfinite(got))
    # Where the mask is 1 a missing depth is still an error.
    holed = renderer.copy()
    holed[5, 6] = np.nan
    with pytest.raises(InvalidInputError, match=r"^depth: expected finite depth > 0 wherever the mask is 1, 1 masked"):
        invsss.render(image, holed, soft, PARAMS)
