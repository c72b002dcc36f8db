"""Specular highlights left out of the fit (``highlights=True``).

Six smooth highlights at half the image's peak are added to a model-made face:
the robust loss alone does not hold the fit (the blobs are too many and too
large to be outliers), leaving them out recovers the truth, and on a photograph
without highlights the option costs next to nothing.
"""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.estimator.stages.highlights import highlight_map
from tests.forward._estimator_scenes import make_pair

PROFILE3 = {"weights": [0.3, 0.45, 0.25], "variances": [0.25, 1.2, 5.0]}
TRUTH = invsss.SSSParams(700.0, 300.0, 2.0, PROFILE3["weights"], PROFILE3["variances"])
SIZE = 80
SPOTS = [(25, 30), (30, 50), (40, 40), (50, 28), (55, 52), (45, 60)]


@pytest.fixture(scope="module")
def scene():
    source, target, depth, mask, clean = make_pair("face", TRUTH, size=SIZE, contrast=3.0, seed=6)
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    specular = sum(np.exp(-((y - cy) ** 2 + (x - cx) ** 2) / (2 * 2.0**2)) for cy, cx in SPOTS)
    photo = target + 0.5 * clean.max() * specular[..., None]
    return source, target, photo, depth, mask, specular


def test_highlight_map_finds_bright_blobs_and_little_else(scene):
    source, target, photo, depth, mask, specular = scene
    _, _, _, _, clean = make_pair("face", TRUTH, size=SIZE, contrast=3.0, seed=6)
    region = mask > 0
    found = highlight_map(photo, clean, region)
    assert all(found[cy, cx] for cy, cx in SPOTS)
    # Away from the blobs (their tails reach the noise level at about 7 px) hardly
    # anything is taken.
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    distance = np.min([np.hypot(y - cy, x - cx) for cy, cx in SPOTS], axis=0)
    assert found[(distance > 8) & region].mean() < 0.01
    assert highlight_map(target, clean, region).sum() < 0.01 * region.sum()


@pytest.mark.slow
def test_leaving_highlights_out_recovers_the_truth(scene):
    source, target, photo, depth, mask, _ = scene
    kw = {"profile": PROFILE3, "n_starts": 2}
    robust_only = invsss.fit_pair(source, photo, depth, mask, **kw)
    assert abs(float(robust_only.params.sss_level) / 700.0 - 1) > 0.2
    fit = invsss.fit_pair(source, photo, depth, mask, highlights=True, **kw)
    assert abs(float(fit.params.sss_level) / 700.0 - 1) < 0.02
    assert abs(float(fit.params.correction) / 300.0 - 1) < 0.03
    record = fit.to_dict()["highlights"]
    assert record["excluded_pixels"][0] > 6 * 10 and 0 < record["fraction"][0] < 0.4
    # Without highlights in the photograph, the option leaves the fit where it was.
    plain = invsss.fit_pair(source, target, depth, mask, **kw)
    checked = invsss.fit_pair(source, target, depth, mask, highlights=True, **kw)
    assert checked.highlights["fraction"][0] < 0.01
    assert abs(float(checked.params.sss_level) - float(plain.params.sss_level)) < plain.stderr["sss_level"]
    assert plain.highlights is None and plain.to_dict()["highlights"] is None
