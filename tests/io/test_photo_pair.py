"""A pair of photographs at one distance (invsss.io.photo_pair.constant_depth_pair): one
depth and the mask it makes, and a distance no face is photographed from is noted once
and used as given."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from invsss.io.photo_pair import constant_depth_pair
from invsss.validation import InputNotice
from tests.io._earlier_fit import disc_mask
from tests.forward._face_photographs import SIZE, face_photographs


@pytest.mark.parametrize("distance, noted", [(50.0, True), (100.0, False), (600.0, False), (5000.0, False),
                                             (1e9, True)])
def test_a_distance_no_face_is_photographed_from_is_noted_once(distance, noted):
    disc = disc_mask()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pair = constant_depth_pair(disc, disc, distance, disc)
    notices = [str(w.message) for w in caught if issubclass(w.category, InputNotice)]
    assert float(pair.depth.max()) == pytest.approx(distance)  # used as given
    expected = [f"distance: {distance:g} mm is outside 100-5000 mm, where a face is photographed from; "
                "used as given, but the fitted sss_level scales with it (is it in mm?)"]
    assert notices == (expected if noted else [])


def test_constant_depth_pair_is_one_depth_and_makes_its_mask():
    rng = np.random.default_rng(4)
    source, target, disc = face_photographs(rng, 500.0)
    pair = constant_depth_pair(source, target, 640.0)
    assert np.all(np.asarray(pair.depth) == 640.0) and pair.depth.shape == (SIZE, SIZE)
    made = np.asarray(pair.mask) > 0.5
    assert (made & (disc > 0)).sum() / (made | (disc > 0)).sum() > 0.95
