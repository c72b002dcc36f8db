"""Renderer-style depth (0 or +inf off the mask) in a fit: the same fit as with a
finite background that continues the surface flat; a masked pixel without depth is
refused by render and fit alike."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.validation import InvalidInputError
from tests.forward._background_scene import PARAMS, scene, with_background


@pytest.mark.slow
def test_fit_with_renderer_background_equals_finite_background():
    image, depth, mask = scene()
    target = np.asarray(invsss.render(image, depth, mask, PARAMS, model="sog"))
    options = dict(n_starts=1, max_steps=15)
    reference = invsss.fit_pair(image, target, depth, mask, **options)
    for background in (0.0, np.inf):
        result = invsss.fit_pair(
            image, target, with_background(depth, mask, background), mask, **options
        )
        assert np.isfinite(result.loss)
        np.testing.assert_allclose(result.loss, reference.loss, rtol=1e-6)
        np.testing.assert_allclose(
            np.asarray(result.params.variances), np.asarray(reference.params.variances), rtol=1e-6
        )


def test_masked_pixel_without_depth_is_refused():
    image, depth, mask = scene()
    holed = depth.copy()
    holed[5, 6] = 0.0  # inside the mask
    with pytest.raises(InvalidInputError, match=r"^depth: .*1 masked pixel\(s\)"):
        invsss.render(image, holed, mask, PARAMS)
    with pytest.raises(InvalidInputError, match=r"^depth: .*1 masked pixel\(s\)"):
        invsss.fit_pair(image, image, holed, mask)
