"""One pair type from files to the estimator, with its checks in one place."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from invsss.estimator.inputs import prepare_pair, prepare_pairs
from invsss.validation import InvalidInputError, check_pair
from tests.forward._pair_arrays import H, W, pair_arrays


def test_tuples_still_work_and_keep_a_2d_target_2d():
    source, target, depth, mask = pair_arrays(target_channels=None)
    with jax.enable_x64(True):
        (data,) = prepare_pairs([(source, target, depth, mask)])
        (no_mask,) = prepare_pairs([(source, target, depth)])
    assert data.target.shape == (H, W, 1) and data.target_ndim == 2
    np.testing.assert_array_equal(np.asarray(no_mask.mask), 1.0)


def test_objects_that_merely_look_like_pairs_are_refused():
    class Lookalike:
        source, target, depth, mask = pair_arrays()

    with pytest.raises(InvalidInputError, match=r"pairs\[0\]: expected .* invsss.ImagePair, got Lookalike"):
        prepare_pairs([Lookalike()])


def test_check_pair_names_the_input_that_is_wrong():
    source, target, depth, mask = pair_arrays()
    names = {"source": "s.exr", "target": "t.exr", "depth": "d.npy", "mask": "m.png"}
    with pytest.raises(InvalidInputError, match=r"^d.npy: expected 6x8 pixels to match s.exr, got 6x7 \(every image of a pair is on one pixel grid"):
        check_pair(source, target, depth[:, :-1], mask, names)
    with pytest.raises(InvalidInputError, match=r"^t.exr: expected 1 channel\(s\) like the source .*, got 3$"):
        check_pair(source[..., :1], target, depth, mask, names)
    with pytest.raises(InvalidInputError, match=r"^pairs\[1\]\.mask: expected values in \[0, 1\], got 0 to 2 \(a 0/255 mask\?"):
        prepare_pair(source, target, depth, mask * 2, name="pairs[1].")
    with pytest.raises(InvalidInputError, match=r"^mask: expected values in \[0, 1\], got -1 to 1$"):
        prepare_pair(source, target, depth, mask * 2 - 1)
