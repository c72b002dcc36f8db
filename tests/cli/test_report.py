"""The report page of a fit (invsss.cli.report): every start's convergence curve over
its own steps, the fitted and the starting profile, and the parameters' caveat."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss import fit_pair
from tests.forward._estimator_scenes import make_pair

# A profile with well separated variances, so every weight is identifiable.
PROFILE3 = {"weights": [0.3, 0.45, 0.25], "variances": [0.25, 1.2, 5.0]}
TRUTH = invsss.SSSParams(700.0, 300.0, 2.0, PROFILE3["weights"], PROFILE3["variances"])


@pytest.fixture(scope="module")
def face_fit():
    """The default-gauge fit of tests/estimator/test_estimator.py's face scene."""
    source, target, depth, mask, _ = make_pair("face", TRUTH, seed=0, contrast=3.0, size=96)
    return fit_pair(source, target, depth, mask, profile=PROFILE3, progress=lambda i, l: None)


@pytest.mark.slow
def test_report_draws_every_start_and_both_profiles(face_fit):
    from matplotlib.figure import Figure

    from invsss.cli.report import parameter_lines, plot_convergence, plot_profile

    result = face_fit
    fig = Figure()
    curve, profile = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    plot_convergence(curve, result)
    # One curve per solve, each over its own steps of the shared iteration axis
    # (a solve may be a single step); the dashed lines mark where rounds begin.
    drawn = [line for line in curve.get_lines() if line.get_linestyle() != "--"]
    assert len(drawn) == len(result.stages)
    assert sorted(int(x) for line in drawn for x in line.get_xdata()) == list(range(1, result.iterations + 1))
    labels = [t.get_text() for t in curve.get_legend().get_texts()]
    assert labels.count("start 1") + labels.count("start 1 (best)") == 1 and sum("(best)" in t for t in labels) == 1
    plot_profile(profile, result)
    fitted, start = profile.get_lines()
    r = np.asarray(fitted.get_xdata())
    expected = invsss.forward.profiles.sum_of_gaussians(r, np.asarray(result.values["weights"]), np.asarray(PROFILE3["variances"]))
    np.testing.assert_allclose(fitted.get_ydata(), np.maximum(np.asarray(expected), 1e-12), rtol=1e-5)
    assert not np.allclose(fitted.get_ydata(), start.get_ydata())
    assert any("conditional on the chosen profile" in line for line in parameter_lines(result))
