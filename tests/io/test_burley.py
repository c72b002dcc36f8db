"""The ``burley`` model's distances as the engines' profiles (invsss.io.engine_profiles):
HDRP's and Unreal's fields converted both ways, and what a pair cannot determine named."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from invsss.io.engine_profiles import (
    engine_profile,
    hdrp_distances,
    hdrp_profile,
    perpendicular_scaling,
    unreal_distances,
    unreal_profile,
)
from tests.forward._burley_scenes import D, burley_params


def test_engine_fields_convert_both_ways():
    d = np.array([3.0, 1.4, 0.9])
    hdrp = hdrp_profile(d, world_scale=0.01)
    assert max(hdrp["scatteringDistance"]) == 1.0 and hdrp["worldScale"] == 0.01
    np.testing.assert_allclose(hdrp_distances(hdrp), d, rtol=1e-14)
    albedo = [0.9, 0.55, 0.4]
    unreal = unreal_profile(d, albedo)
    # Christensen & Burley's perpendicular fit typed in again, s = 1.85 - A + 7 |A - 0.8|^3,
    # with Unreal's 0.6 between its mean free path and d (Dmfp2MfpMagicNumber).
    s = np.array([1.85 - a + 7 * abs(a - 0.8) ** 3 for a in albedo])
    np.testing.assert_allclose(np.asarray(unreal["MeanFreePathColor"]) * unreal["MeanFreePathDistance"],
                               0.6 * d * s / 10.0, rtol=1e-14)  # cm
    np.testing.assert_allclose(unreal_distances(unreal), d, rtol=1e-14)
    assert perpendicular_scaling(0.8) == pytest.approx(1.05)


def test_export_names_what_the_pair_cannot_determine():
    with jax.enable_x64(True):
        p = burley_params()
    hdrp = engine_profile(p, "hdrp")
    assert set(hdrp["undetermined"]) >= {"worldScale", "indexOfRefraction"}
    np.testing.assert_allclose(hdrp_distances(hdrp["fields"]), D, rtol=1e-12)
    given = engine_profile(p, "unreal", albedo=[0.9, 0.5, 0.4], world_scale=0.1, mm_per_unit=10.0)
    assert "SurfaceAlbedo" not in given["undetermined"] and "WorldUnitScale" not in given["undetermined"]
    np.testing.assert_allclose(unreal_distances(given["fields"]), 10.0 * D, rtol=1e-12)
    assumed = engine_profile(p, "unreal")
    assert "SurfaceAlbedo" in assumed["undetermined"]
