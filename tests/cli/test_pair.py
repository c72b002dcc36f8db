"""The pair that load_pair reads from files is the type the estimator takes, as the
command line hands it on."""

from __future__ import annotations

import jax
import numpy as np

import invsss
from invsss.estimator.inputs import prepare_pairs
from invsss.forward.pair import ImagePair
from tests.forward._pair_arrays import pair_arrays


def test_load_pair_and_the_estimator_share_one_type(tmp_path):
    source, target, depth, mask = (a.astype(np.float32) for a in pair_arrays())
    paths = [tmp_path / n for n in ("s.exr", "t.exr", "d.npy", "m.npy")]
    invsss.write_image(paths[0], source)
    invsss.write_image(paths[1], target)
    np.save(paths[2], depth)
    np.save(paths[3], mask)
    pair = invsss.load_pair(*paths)
    assert type(pair) is ImagePair and invsss.ImagePair is ImagePair
    with jax.enable_x64(True):
        (data,) = prepare_pairs([pair])
    assert type(data) is ImagePair and data.source.dtype == np.float64
    assert data.channels == (3, 3) and data.target_ndim == 3
