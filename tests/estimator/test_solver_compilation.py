"""Compiling ahead of the call: solve.compile_solver, and the fit compiling its solver
step on a second thread while the start scan runs. (persistent_jit.prepare itself:
tests/runtime/test_executable_cache.py.)"""

from __future__ import annotations

import threading

import jax
import numpy as np
import pytest

import invsss
from invsss.estimator import FitOptions, build_problem
from invsss.estimator.solve import NOISE_TOL, RTOL, SCREEN_TOL, compile_solver, make_solver, run_solver

from tests.runtime._compilations import Compilations
from tests.forward._estimator_scenes import make_pair

SOLVER_JACOBIAN = FitOptions().solver_jacobian  # the fit's default

PROFILE3 = {"weights": [0.3, 0.45, 0.25], "variances": [0.25, 1.2, 5.0]}
TRUTH = invsss.SSSParams(700.0, 300.0, 2.0, PROFILE3["weights"], PROFILE3["variances"])


def _scene(size, seed=0):
    source, target, depth, mask, _ = make_pair("face", TRUTH, size=size, contrast=3.0, seed=seed)
    return source, target, depth, mask


@pytest.mark.slow
def test_compile_solver_leaves_the_solve_nothing_to_compile():
    # A size no other test compiles, so the counts are this test's own.
    # start={}: no scan, so nothing but the solver compiles here.
    problem = build_problem([_scene(27, seed=4)], FitOptions(profile=PROFILE3), start={})
    with jax.enable_x64(True), Compilations("_init", "_step") as compiled:
        # The screening solver, from z_base: what the fit compiles with.
        compile_solver(make_solver("lm", tolerance=SCREEN_TOL), problem.objective,
                       np.asarray(problem.z_base, np.float64), NOISE_TOL, SOLVER_JACOBIAN)
        assert compiled.count("_init") == 1 and compiled.count("_step") == 1
        # The full-tolerance solver from another point, as the fit's refinement runs it.
        record = run_solver(make_solver("lm", tolerance=RTOL), problem.objective, problem.z0 + 0.1, 4,
                            noise_tolerance=NOISE_TOL, jacobian=SOLVER_JACOBIAN)
        assert compiled.count() == 2
    assert record.steps >= 1 and np.isfinite(record.final)


@pytest.mark.slow  # a whole fit (cold compilation at a new size)
def test_a_fit_compiles_its_step_once_on_the_second_thread():
    pair = _scene(30, seed=5)
    with Compilations("_step", "evaluate") as compiled:
        fit = invsss.fit_pair(*pair, options=FitOptions(profile=PROFILE3, n_starts=2))
    # The scan's loss compiled on the caller's thread, the step once, beside it.
    assert compiled.seen.count(("jit(evaluate)", threading.current_thread().name)) == 1
    assert [thread for fun, thread in compiled.seen if fun == "jit(_step)"] == ["invsss-compile-solver"]
    assert fit.converged
