"""The estimator's look at its inputs (invsss.estimator.inputs): a mask that spills
onto the depth's far plane is noted."""

from __future__ import annotations

import warnings

import numpy as np

import invsss

H, W = 12, 16  # non-square, so a transposed read cannot pass


def _mask_notices(func) -> list[str]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        func()
    return [str(w.message) for w in caught if issubclass(w.category, invsss.InputNotice)]


def test_a_mask_on_the_far_plane_is_noted(tmp_path):
    from invsss.estimator.inputs import prepare_pair

    image = np.ones((H, W, 3))
    depth = np.full((H, W), 500.0)
    skin = np.zeros((H, W))
    skin[2:8, 2:6] = 1.0
    assert _mask_notices(lambda: prepare_pair(image, image, depth, skin)) == []  # one flat plane
    depth[:, W // 2:] = 1e4  # the right half is background at the far plane
    assert _mask_notices(lambda: prepare_pair(image, image, depth, skin)) == []
    skin[2:8, W // 2: W // 2 + 3] = 1.0  # spills onto the background
    notes = _mask_notices(lambda: prepare_pair(image, image, depth, skin))
    assert len(notes) == 1 and "18 masked pixel(s) lie on the depth's far plane (10000)" in notes[0]
