"""A small pair of random arrays with a rectangular mask (the tests of ImagePair and prepare_pairs)."""

from __future__ import annotations

import numpy as np

H, W = 6, 8


def pair_arrays(target_channels=3):
    """``(source, target, depth, mask)``: an RGB source, a target of ``target_channels``
    channels (None: an (H, W) target), a flat depth of 500 and a 4 x 4 mask."""
    rng = np.random.default_rng(0)
    mask = np.zeros((H, W))
    mask[1:5, 2:6] = 1.0
    target_shape = (H, W) if target_channels is None else (H, W, target_channels)
    return rng.random((H, W, 3)), rng.random(target_shape), np.full((H, W), 500.0), mask
