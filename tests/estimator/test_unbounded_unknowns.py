"""A fit whose data bound an unknown on one side only ends with finite values and
a report, not an overflow.

On pt_proc_ear_glow_940 the plain fit takes the correction to 0, after which maxdd
changes nothing and walks off: before
:data:`~invsss.estimator.parametrisation.LOG_LIMIT` it ended at 5.9e44, infinite
in the float32 parameters returned (with NumPy's overflow warning), and with the
target changed by one part in 1e12 the fit raised ``LinAlgError`` from its
uncertainty. Where the walk ends depends on rounding (the test suite's XLA
options end that fit elsewhere), so the test starts the solve far out instead.
"""

from __future__ import annotations

import warnings

import numpy as np

import invsss
from invsss.estimator import FitOptions
from invsss.estimator.core import FitCall, Start, core


def test_a_start_far_along_an_unbounded_maxdd_ends_finite_and_reported():
    rng = np.random.default_rng(0)
    source = rng.uniform(0.2, 1.0, (24, 24))
    # A plane: every depth slope is the same small one, so any maxdd above it gives
    # the same image; only a bound below is measured.
    depth = 500.0 + 0.2 * np.arange(24)[None, :] * np.ones((24, 1))
    mask = np.ones((24, 24))
    truth = invsss.SSSParams(600.0, 0.5, 5.0, [0.6, 0.4], [0.5, 2.0])
    target = np.asarray(invsss.render(source, depth, mask, truth))
    options = FitOptions(profile={"weights": [0.6, 0.4], "variances": [0.5, 2.0]}, n_starts=1)
    start = Start({"sss_level": 600.0, "correction": 0.5, "maxdd": 1e300})
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        fit = core(FitCall([(source, target, depth, mask)], True, options, start=start))
    assert np.isfinite(float(fit.values["maxdd"])) and np.isfinite(float(fit.params.maxdd))
    assert float(fit.values["maxdd"]) > 1e20  # held at the limit: the data never pulled it back
    assert "maxdd" in fit.undetermined
    assert abs(float(fit.values["sss_level"]) / 600.0 - 1.0) < 0.01



def test_a_log_unknown_past_the_limit_is_reported_undetermined():
    """Past the limit a scale moves with no unknown, so the standard error the
    covariance gives it is 0: an exact value, where the data only bound it. Linearised
    with maxdd's unknown at 837 (where pt_proc_ear_glow_940's walk ended), maxdd is
    reported undetermined; the blur scale, measured, is not."""
    import jax

    from invsss.estimator import build_problem
    from invsss.estimator.uncertainty import gauss_newton_uncertainty, linearise

    rng = np.random.default_rng(1)
    source = rng.uniform(0.2, 1.0, (24, 24))
    depth = 500.0 + 0.2 * np.arange(24)[None, :] * np.ones((24, 1))
    mask = np.ones((24, 24))
    target = np.asarray(invsss.render(source, depth, mask, invsss.SSSParams(600.0, 0.5, 5.0, [0.6, 0.4], [0.5, 2.0])))
    target = target + rng.normal(0.0, 0.01, target.shape)
    problem = build_problem([(source, target, depth, mask)],
                            FitOptions(profile={"weights": [0.6, 0.4], "variances": [0.5, 2.0]}, robust=None,
                                       n_starts=1))
    first, _ = problem.param.layout()["maxdd"]
    with jax.enable_x64(True):
        z = np.asarray(problem.starts[0]).copy()
        z[first] = 837.0
        z = jax.device_put(z)
        _, _, _, coef, offset = problem.objective.linear(z)
        lin = jax.tree_util.tree_map(np.asarray, linearise(problem.objective, z, coef, offset))
        unc = gauss_newton_uncertainty(problem.objective, lin, problem.scales.correction, None, None)
    assert np.all(np.asarray(lin["value_jacobians"]["maxdd"]) == 0)  # what would make it look exact
    assert bool(unc.undetermined["maxdd"]) and np.isnan(float(unc.stderr["maxdd"]))
    assert not bool(unc.undetermined["sss_level"])
