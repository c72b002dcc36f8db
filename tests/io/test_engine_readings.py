"""The engines' assets read back as the engines read them (issue 46).

``invsss.io.engine_profiles`` writes an HDRP Diffusion Profile or an Unreal Subsurface
Profile from Burley's ``d``; ``invsss.io.engine_readings`` follows each engine's own
code from those fields to the ``d`` it renders. Export then reading must give ``d``
back, over the albedos and distances skin and its exports span, including the
distances under Unreal's 0.1 cm clamp.
"""

from __future__ import annotations

import numpy as np
import pytest

from invsss.io.engine_profiles import hdrp_profile, unreal_profile
from invsss.io.engine_readings import (UNREAL_LIMITS, hdrp_reading, hdrp_transmittance, unreal_reading,
                                      unreal_transmittance)
from invsss.validation import InvalidInputError

ALBEDOS = np.linspace(0.05, 0.95, 20)
SCALES = np.geomspace(0.05, 5.0, 9)  # the widest channel's d, mm
RATIOS = ([1.0, 1.0, 1.0], [1.0, 0.5, 0.25], [0.25, 1.0, 0.5], [1.0, 0.1, 0.01])


def _profiles():
    for scale in SCALES:
        for ratio in RATIOS:
            d = scale * np.asarray(ratio)
            if d.min() >= 0.05 - 1e-12:  # the range, 0.05 to 5 mm
                yield d


@pytest.mark.parametrize("albedo", ALBEDOS)
def test_unreal_renders_the_exported_distances(albedo):
    for d in _profiles():
        fields = unreal_profile(d, albedo)
        np.testing.assert_allclose(unreal_reading(fields), d, rtol=1e-6)


def test_unreal_reads_per_channel_albedos():
    albedo = [0.91058, 0.338275, 0.2718]  # Unreal's default SurfaceAlbedo
    for d in _profiles():
        np.testing.assert_allclose(unreal_reading(unreal_profile(d, albedo)), d, rtol=1e-6)


def test_unreal_fields_stay_inside_the_editor_ranges():
    # Fitted skin (0.25-1.29 mm) lies mostly under the 0.1 cm distance floor: the
    # export must move the scale into the colour, not write a distance the editor clamps.
    low, high = UNREAL_LIMITS["MeanFreePathDistance"]
    for albedo in (0.05, 0.5, 0.95):
        for d in _profiles():
            fields = unreal_profile(d, albedo)
            assert low <= fields["MeanFreePathDistance"] <= high
            colour = np.asarray(fields["MeanFreePathColor"])
            assert colour.max() <= 1.0 and colour.min() >= UNREAL_LIMITS["render_floor"]
            assert fields["Implementation"] == "SIH_AFIS"
            assert fields["bEnableBurley"] is True and fields["bEnableMeanFreePath"] is True
    skin = unreal_profile([1.29, 0.6, 0.25], [0.9, 0.55, 0.4])
    assert skin["MeanFreePathDistance"] == 0.1 and max(skin["MeanFreePathColor"]) < 1.0


def test_unreal_reading_applies_the_engines_own_factor():
    # Typed from SubsurfaceProfile.cpp: dmfp = mfp * s_sl / s_perp * 10 / 0.6 (mm), and
    # the shader's profile takes d = dmfp / s_sl; A = 0.8: s_perp = 1.05.
    fields = {"SurfaceAlbedo": [0.8] * 3, "MeanFreePathColor": [1.0, 0.5, 0.25], "MeanFreePathDistance": 0.63}
    np.testing.assert_allclose(unreal_reading(fields), [10.0, 5.0, 2.5], rtol=1e-12)
    # A distance under the editor's floor is held at 0.1 cm, as the editor holds it.
    small = dict(fields, MeanFreePathDistance=0.02)
    np.testing.assert_allclose(unreal_reading(small), unreal_reading(dict(fields, MeanFreePathDistance=0.1)))


def test_unreal_refuses_what_the_engine_would_clamp():
    with pytest.raises(InvalidInputError, match="0.009"):
        unreal_profile([5.0, 0.5, 0.02], 0.5)  # a channel 250x narrower than the widest
    with pytest.raises(InvalidInputError, match="50 cm"):
        unreal_profile([600.0, 300.0, 150.0], 0.5)
    with pytest.raises(InvalidInputError, match="500 mm"):
        unreal_profile([200.0, 100.0, 50.0], 0.5)  # l = 18.5 cm, but d s_sl(A) = 700 mm
    for albedo in (0.0, [0.9, 0.5], "pale"):
        with pytest.raises(InvalidInputError, match="albedo"):
            unreal_profile([1.0, 0.5, 0.25], albedo)
    with pytest.raises(InvalidInputError, match="bEnableMeanFreePath"):
        unreal_reading(dict(unreal_profile([1.0, 0.5, 0.25], 0.5), bEnableMeanFreePath=False))


@pytest.mark.parametrize("world_scale", [0.01, 1.0])
def test_hdrp_renders_the_exported_distances(world_scale):
    for d in _profiles():
        fields = hdrp_profile(d, world_scale=world_scale)
        np.testing.assert_allclose(hdrp_reading(fields), d, rtol=1e-6)
        assert max(fields["scatteringDistance"]) == 1.0


def test_hdrp_reading_caps_the_shape_parameter():
    # HDRP's UpdateKernel: S = min(2^24, 1 / sd), so a zero channel renders d = 2^-24 mm.
    d = hdrp_reading({"scatteringDistance": [1.0, 0.0, 0.5], "scatteringDistanceMultiplier": 2.0})
    np.testing.assert_allclose(d, [2.0, 2.0**-24, 1.0])


@pytest.mark.parametrize("d_mm", [0.3, 1.0, 4.0])
@pytest.mark.parametrize("map_mm", [2.0, 5.0, 20.0])
def test_hdrp_transmits_what_the_fitted_term_transmits(d_mm, map_mm):
    # Issue 48: the term's tint * T(k t) (invsss.forward.transmission) against HDRP's reading
    # of the exported fields, on a thickness map of t / map_mm.
    from invsss.forward.transmission import burley_transmittance
    from invsss.io.engine_profiles import hdrp_transmission

    tint, k = np.array([0.9, 0.45, 0.2]), 0.3
    fields = {**hdrp_profile([d_mm] * 3), **hdrp_transmission(tint, k, [d_mm] * 3, map_mm)}
    thickness = np.linspace(0.0, map_mm, 11)
    expected = tint * np.asarray(burley_transmittance(k * thickness), np.float64)[:, None]
    np.testing.assert_allclose(hdrp_transmittance(fields, thickness / map_mm), expected, rtol=1e-6)
    # A remap without the profile's d (the slope k * map_mm alone) would be read wrong.
    wrong = {**fields, "thicknessRemap": [0.0, k * map_mm]}
    assert not np.allclose(hdrp_transmittance(wrong, thickness / map_mm), expected, rtol=1e-3) or d_mm == 1.0


def test_hdrp_transmission_needs_one_distance():
    from invsss.io.engine_profiles import hdrp_transmission

    with pytest.raises(InvalidInputError, match="Burley's d differs by channel"):
        hdrp_transmission(0.5, 0.3, [1.0, 0.5, 0.25])
    with pytest.raises(InvalidInputError, match="transmission: expected a tint >= 0"):
        hdrp_transmission(-0.1, 0.3, [1.0, 1.0, 1.0])


@pytest.mark.parametrize("d_mm, world_unit_scale", [(0.5, 1.0), (1.0, 1.0), (2.0, 0.5), (4.0, 0.1)])
def test_unreal_transmits_what_the_fitted_term_transmits(d_mm, world_unit_scale):
    # Issue 48: where Unreal's table covers the thicknesses (from 4.5 to about 48 profile mm
    # over WorldUnitScale / 0.1, against k d t), its reading of the exported fields follows the
    # term's tau T(k t) within its 32-entry table's interpolation.
    from invsss.forward.transmission import burley_transmittance
    from invsss.io.unreal_transmission import unreal_transmission

    tau, k = np.array([0.5, 0.3, 0.1]), 0.25
    extra, match = unreal_transmission(tau, k, [d_mm] * 3, world_unit_scale, (1.0, 10.0))
    fields = {**unreal_profile([d_mm] * 3, albedo=0.6, world_unit_scale=world_unit_scale), **extra}
    thickness = np.linspace(1.0, 10.0, 1000)
    fitted = tau * np.asarray(burley_transmittance(k * thickness), np.float64)[:, None]
    ratio = unreal_transmittance(fields, thickness) / fitted
    # What the export says Unreal renders is what Unreal's reading renders (but for the
    # 16-bit texture), and here that is the fitted light within 6 %.
    claimed = np.array(match["renderedOverFitted"])
    np.testing.assert_allclose(ratio.min(axis=0), claimed[:, 0], rtol=3e-3)
    np.testing.assert_allclose(ratio.max(axis=0), claimed[:, 1], rtol=3e-3)
    np.testing.assert_allclose(ratio, 1.0, atol=0.06)
    # Without WorldUnitScale's square in ExtinctionScale the slope is read wrong.
    if world_unit_scale != 0.1:
        wrong = {**fields, "ExtinctionScale": extra["ExtinctionScale"] * 0.1 / world_unit_scale}
        assert not np.allclose(unreal_transmittance(wrong, thickness), fitted, rtol=0.1)


def test_unreal_reports_the_light_its_table_cannot_start_with():
    # d = 1 mm at the default WorldUnitScale: the table starts at 4.5 profile mm, the tint
    # would have to exceed 1; the export says what share Unreal renders and the reading agrees.
    from invsss.forward.transmission import burley_transmittance
    from invsss.io.unreal_transmission import unreal_transmission

    extra, match = unreal_transmission(0.55, 0.29, [1.0] * 3, 0.1, (1.0, 10.0))
    assert extra["TransmissionTintColor"] == [1.0, 1.0, 1.0] and match["tableStartMm"] == pytest.approx(4.475)
    fields = {**unreal_profile([1.0] * 3, albedo=0.6), **extra}
    thickness = np.linspace(1.0, 10.0, 1000)
    ratio = unreal_transmittance(fields, thickness)[:, 0] / (0.55 * np.asarray(burley_transmittance(0.29 * thickness)))
    lo, hi = match["renderedOverFitted"][0]
    assert ratio.min() == pytest.approx(lo, rel=3e-3) and ratio.max() == pytest.approx(hi, rel=3e-3) and hi < 0.7
    # d = 2 mm at WorldUnitScale 1: the table ends (black) at about 4.9 profile mm, k d t = 5 mm.
    extra, match = unreal_transmission(0.55, 0.25, [2.0] * 3, 1.0, (1.0, 10.0))
    fields = {**unreal_profile([2.0] * 3, albedo=0.6, world_unit_scale=1.0), **extra}
    assert match["renderedOverFitted"][0][0] == 0.0 and unreal_transmittance(fields, 10.0)[0] == 0.0


def test_unreal_transmission_reads_the_engines_clamps_and_black_end():
    base = {"SurfaceAlbedo": [0.8] * 3, "MeanFreePathColor": [1.0] * 3, "MeanFreePathDistance": 0.1,
            "WorldUnitScale": 1.0, "TransmissionTintColor": [2.0, 0.5, 0.0], "ExtinctionScale": 3.0,
            "NormalScale": 0.0}
    read = unreal_transmittance(base, [0.0, 100.0])
    # The tint held to [0.009, 1]; the floor of the optical depth (0.15 + 0.25) at no thickness;
    # past the table's last entry (black) nothing.
    np.testing.assert_allclose(read[0] / read[0, 0], [1.0, 0.5, 0.009], rtol=2e-3)  # 16-bit texture
    assert np.all(read[1] == 0.0)
    assert np.all(unreal_transmittance(base, 0.0) == unreal_transmittance(base, 0.3))


def test_unreal_transmission_needs_one_distance():
    from invsss.io.unreal_transmission import unreal_transmission

    with pytest.raises(InvalidInputError, match="Unreal's ExtinctionScale is one per profile"):
        unreal_transmission(0.5, 0.3, [1.0, 0.5, 0.25])
    with pytest.raises(InvalidInputError, match="thickness_range_mm: expected 0 < low < high"):
        unreal_transmission(0.5, 0.3, [1.0] * 3, 0.1, (3.0, 1.0))
