"""Clipped pixels of a photograph are left out of the fit (``saturation=``).

A pixel at the sensor's top code reads darker than the light that reached it; the
model, which knows no ceiling, bends to match it. Checked on a model-made card
whose target is clipped at a level a fifth of its pixels reach (kept in, they
move sss_level by +38 %; left out, -0.4 %).

The clipping level of files, the command line and sweeps are tested in the folders
of their layers (test_saturation.py in each).
"""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from tests.forward._clipped_card import FIX, PROFILE, clipped_card


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore::invsss.InputNotice")
def test_clipped_pixels_are_left_out_and_counted():
    source, target, depth, mask, level = clipped_card()
    kept = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1, saturation=level)
    bent = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1)
    error = {name: abs(float(fit.values["sss_level"]) / 375.0 - 1.0) for name, fit in (("kept", kept), ("bent", bent))}
    assert error["kept"] < 0.02
    assert error["bent"] > 3 * error["kept"]
    count = int(np.sum(target >= level))
    assert any(f"{count} masked pixel(s) at or above the saturation level" in w for w in kept.warnings)
    assert not any("saturation" in w for w in bent.warnings)


@pytest.mark.parametrize("level", [0.0, -1.0, float("nan"), "high", True])
def test_a_bad_saturation_level_is_a_one_line_error(level):
    source, target, depth, mask, _ = clipped_card()
    with pytest.raises(invsss.InvalidInputError, match="^saturation: expected a number > 0, 'auto' or None"):
        invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, saturation=level)


def test_a_level_below_every_pixel_leaves_nothing_to_fit():
    source, target, depth, mask, _ = clipped_card()
    with pytest.raises(invsss.InvalidInputError, match="^target: every masked pixel is at or above"):
        invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, saturation=1e-9)


def test_auto_is_an_option_value_that_arrays_alone_cannot_resolve():
    # "auto" is one value from the option table to the stage: the targets' own level,
    # which their files know (invsss.io.resolved_saturation); arrays do not say it.
    assert invsss.FitOptions(saturation="auto").saturation == "auto"
    source, target, depth, mask, _ = clipped_card()
    with pytest.raises(invsss.InvalidInputError, match="^saturation: 'auto' is the targets' own clipping level"):
        invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, saturation="auto")
