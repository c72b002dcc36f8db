"""Standard errors of an aligned fit count the warp as estimated.

The covariance takes extra (nuisance) columns: checked against the marginal
covariance computed directly with NumPy, and for the two limits (a column the
other unknowns cannot see changes nothing but the degrees of freedom; a copy of
a parameter's own column leaves it undetermined). The warp's columns are checked
against the prediction shifted instead: moving the source side moves the
prediction with it.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.estimator import FitOptions, build_problem
from invsss.estimator.stages.alignment import WarpSensitivity
from invsss.estimator.uncertainty import gauss_newton_uncertainty, linearise
from invsss.forward.pair import ImagePair
from invsss.estimator.registration import Warp, align_source

from tests.forward._estimator_scenes import make_pair

PROFILE = {"weights": [0.3, 0.45, 0.25], "variances": [0.25, 1.2, 5.0]}
TRUTH = invsss.SSSParams(700.0, 300.0, 2.0, PROFILE["weights"], PROFILE["variances"])


@pytest.fixture(scope="module")
def linearised():
    """A plain least-squares problem at its start point, linearised as the fit does."""
    source, target, depth, mask, _ = make_pair("face", TRUTH, seed=1, contrast=3.0, size=48)
    problem = build_problem([(source, target, depth, mask)], FitOptions(profile=PROFILE, robust=None))
    with jax.enable_x64(True):
        z = problem.z0
        _, _, _, coef, offset = problem.objective.linear(z)
        lin = jax.tree_util.tree_map(np.asarray, linearise(problem.objective, z, coef, offset))
    return problem, lin


def _uncertainty(problem, lin, nuisance=None):
    # The white-noise covariance, whose formula these tests check (the
    # cluster-robust one is tested in test_correlated_noise.py).
    with jax.enable_x64(True):
        return gauss_newton_uncertainty(problem.objective, lin, problem.scales.correction, None, nuisance,
                                        blocks=False)


@pytest.mark.slow
def test_a_nuisance_column_gives_the_marginal_covariance(linearised):
    problem, lin = linearised
    J, r = lin["jacobian"], lin["residual"]
    rng = np.random.default_rng(0)
    # Correlated with the sss_level column (the first unknown), plus its own part.
    extra = J[:, :1] + 0.5 * np.linalg.norm(J[:, 0]) / np.sqrt(J.shape[0]) * rng.standard_normal((J.shape[0], 1))
    extra *= np.asarray(problem.objective.weights()[0]).ravel()[:, None] > 0
    got = _uncertainty(problem, lin, extra)
    n = int(sum(np.sum(np.asarray(w) > 0) for w in problem.objective.weights()))
    augmented = np.concatenate([J, extra], axis=1)
    cov = np.sum(r**2) / (n - augmented.shape[1]) * np.linalg.inv(augmented.T @ augmented)
    # sss_level = reference * exp(z_0): its standard error is sss_level * se(z_0).
    level = float(lin["values"]["sss_level"])
    assert float(got.stderr["sss_level"]) == pytest.approx(level * np.sqrt(cov[0, 0]), rel=1e-6)
    assert float(got.nuisance_stderr[0]) == pytest.approx(np.sqrt(cov[-1, -1]), rel=1e-6)
    # Estimating a correlated unknown as well can only widen the error.
    assert float(got.stderr["sss_level"]) > 1.01 * float(_uncertainty(problem, lin).stderr["sss_level"])


@pytest.mark.slow
def test_a_column_the_others_cannot_see_changes_only_the_degrees_of_freedom(linearised):
    problem, lin = linearised
    J = lin["jacobian"]
    rng = np.random.default_rng(1)
    seen = np.asarray(problem.objective.weights()[0]).ravel() > 0
    extra = rng.standard_normal(J.shape[0]) * seen
    extra -= J @ np.linalg.lstsq(J, extra, rcond=None)[0]  # orthogonal to every column of J
    n = int(seen.sum())
    plain, more = _uncertainty(problem, lin), _uncertainty(problem, lin, extra[:, None])
    dof_ratio = np.sqrt((n - J.shape[1]) / (n - J.shape[1] - 1))
    assert float(more.stderr["sss_level"]) == pytest.approx(dof_ratio * float(plain.stderr["sss_level"]), rel=1e-6)


@pytest.mark.slow
def test_a_copy_of_a_parameter_column_leaves_it_undetermined(linearised):
    problem, lin = linearised
    got = _uncertainty(problem, lin, lin["jacobian"][:, :1].copy())
    assert got.undetermined["sss_level"].all() and not np.isfinite(got.stderr["sss_level"]).any()
    assert np.isnan(got.nuisance_stderr[0])


@pytest.mark.slow
def test_the_shift_columns_are_the_gradient_of_the_prediction():
    source, target, depth, mask, _ = make_pair("wave", TRUTH, seed=2, contrast=3.0, size=48)
    warp = Warp("translation", (0.3, -0.2), (23.5, 23.5))
    moved, moved_depth, kept = align_source(source, depth, mask, warp, target.shape[:2])
    pair = ImagePair(moved, target, moved_depth, kept)
    problem = build_problem([pair], FitOptions(profile=PROFILE, robust=None))
    checked = [(np.asarray(source, np.float64), np.asarray(target, np.float64)[..., None],
                np.asarray(depth, np.float64), np.asarray(mask, np.float64), 2)]
    with jax.enable_x64(True):
        z = problem.z0
        _, _, _, coef, offset = problem.objective.linear(z)
        columns = WarpSensitivity(checked, [warp]).columns(problem.objective, z, coef, offset)
        prediction = np.asarray(problem.objective.predictions(z)[0])[..., 0]
    weight = np.sqrt(np.asarray(problem.objective.weights()[0])[..., 0]) / float(problem.objective.scale)
    # Moving the source side by +t moves the prediction by +t (the blur follows the
    # image): d(pred)/dt is the prediction's own shift, differentiated with the same
    # cubic spline, and the residual (target - pred) changes by minus that.
    h = 0.05
    # Away from the mask's rim, where the resampled mask itself moves.
    inside = ndimage.binary_erosion(np.asarray(pair.mask) == 1, iterations=2)
    for axis in (0, 1):
        step = np.zeros(2)
        step[axis] = h
        d_pred = (ndimage.shift(prediction, step, order=3, mode="nearest")
                  - ndimage.shift(prediction, -step, order=3, mode="nearest")) / (2 * h)
        expected = (-weight * d_pred)[inside]
        got = columns[:, axis].reshape(prediction.shape)[inside]
        # Not exact: the depth moves too, and the stretch follows its resampled slopes
        # (measured: correlation 0.979 and 0.989, slope 1.03 and 1.02).
        assert np.corrcoef(got, expected)[0, 1] > 0.97
        assert float(got @ expected / (expected @ expected)) == pytest.approx(1.0, abs=0.05)
