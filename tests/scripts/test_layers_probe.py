"""The shadow-edge layer of experiments/layers_probe.py (issue 29, item 5): that its
signed distances are the ones across a known edge, that the terminator is left out,
and that its images can carry any 1-D profile across the edge, so that a gain of
nothing from it means the residual has no such profile."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest
from tests import ROOT

pytest.importorskip("mitsuba")  # the probe's helpers read scene configs with invsss.scenes

_PATH = ROOT / "experiments" / "layers_probe.py"
_SPEC = importlib.util.spec_from_file_location("layers_probe", _PATH)
layers_probe = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(layers_probe)
sys.path.remove(str(_PATH.parent))  # the probe puts experiments/ first on the path


def _half_lit(mu0_value=0.8, width=40, edge=20):
    """Key light 2.0 on columns < ``edge`` and 0.05 beyond (a cast shadow), 30 rows."""
    key = np.full((30, width, 1), 0.05)
    key[:, :edge] = 2.0
    mu0 = np.full((30, width, 1), mu0_value)
    return key, mu0, np.ones((30, width))


def test_signed_distances_across_a_vertical_edge():
    key, mu0, mask = _half_lit()
    layers, near = layers_probe.shadow_edge_profiles(key, mu0, mask, reach=3, bins=1)
    assert len(layers) == 6  # steps -3..2
    # Step d marks column 19 - d: 0 on the last lit column, -1 on the first shadowed one.
    for d, image in zip(range(-3, 3), layers):
        columns = np.flatnonzero(image[0, :, 0])
        assert columns.tolist() == [19 - d]
        assert np.all(image[:, 19 - d, 0] == 2.0)  # the lit level beside the edge
    assert np.flatnonzero(near[0]).tolist() == list(range(17, 23))


def test_the_terminator_is_not_an_edge():
    key, mu0, mask = _half_lit(mu0_value=0.1)
    layers, near = layers_probe.shadow_edge_profiles(key, mu0, mask, reach=3, bins=1)
    assert layers == [] and not near.any()


def test_any_profile_across_the_edge_is_taken_up():
    key, mu0, mask = _half_lit()
    rng = np.random.default_rng(0)
    prediction = 1.0 + 0.1 * rng.random(key.shape)
    profile = np.zeros(40)
    profile[13:27] = rng.standard_normal(14) * 0.05
    target = prediction + profile[None, :, None] * 2.0
    layers, _ = layers_probe.shadow_edge_profiles(key, mu0, mask, reach=7, bins=1)
    columns = np.stack([prediction[..., 0].ravel()] + [l[..., 0].ravel() for l in layers] + [np.ones(1200)], 1)
    weights, *_ = np.linalg.lstsq(columns, target[..., 0].ravel(), rcond=None)
    assert np.max(np.abs(columns @ weights - target[..., 0].ravel())) < 1e-10
    without = np.linalg.lstsq(columns[:, [0, -1]], target[..., 0].ravel(), rcond=None)[1]
    assert without[0] > 0.01  # the profile is not in the prediction alone
