"""The estimator's look at its inputs (invsss.estimator.inputs): a mask that spills
onto the depth's far plane is noted."""

from __future__ import annotations

import numpy as np

from tests.forward._notices import input_notices

H, W = 12, 16  # non-square, so a transposed read cannot pass


def test_a_mask_on_the_far_plane_is_noted(tmp_path):
    from invsss.estimator.inputs import prepare_pair

    image = np.ones((H, W, 3))
    depth = np.full((H, W), 500.0)
    skin = np.zeros((H, W))
    skin[2:8, 2:6] = 1.0
    assert input_notices(lambda: prepare_pair(image, image, depth, skin)) == []  # one flat plane
    depth[:, W // 2:] = 1e4  # the right half is background at the far plane
    assert input_notices(lambda: prepare_pair(image, image, depth, skin)) == []
    skin[2:8, W // 2: W // 2 + 3] = 1.0  # spills onto the background
    notes = input_notices(lambda: prepare_pair(image, image, depth, skin))
    assert len(notes) == 1 and "18 masked pixel(s) lie on the depth's far plane (10000)" in notes[0]
