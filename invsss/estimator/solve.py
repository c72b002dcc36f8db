"""Running an optimistix solver one step at a time.

The loop is written out (``solver.init``, a jitted ``solver.step``,
``solver.terminate``) instead of calling ``optx.least_squares`` so that each
iteration can report its loss to a progress callback and the loss history can be
kept. The step is compiled once per problem layout: the objective is passed as an
argument (its arrays are traced), so every start and every re-solve with new
robust weights or a new active set reuses it.

Solvers: ``"lm"`` (Levenberg-Marquardt, default), ``"gauss-newton"`` and
``"bfgs"`` (which minimises ``0.5 * sum(residual^2)``).

This is the package's one way to run a solver: the estimator and
:func:`invsss.fit_sum_of_gaussians` both call :func:`run_solver`. Between two steps
(outside compiled code) it polls a ``stop`` callable, so a fit can be interrupted
cleanly and still report the best point reached.

On a GPU the loop steps ahead (:func:`step_ahead`): it dispatches step ``i + 1``
before it reads step ``i``'s loss, so the device works on the next step while
the host reads the last one back, runs the callbacks and tests for the end.
A solve that ends at step ``i`` throws step ``i + 1`` away; its record is the
one the plain loop returns, bit for bit.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..runtime.executable_cache import StaleStatics, persistent_jit
from ..validation import InvalidInputError

__all__ = [
    "SOLVERS", "JACOBIANS", "DIFFERENCE_STEP", "SCREEN_TOL", "NOISE_TOL", "STALL_TOL",
    "SCREEN_STALL_TOL", "STALL_WINDOW", "gauss_newton_distance", "stalled", "make_solver",
    "SolveRecord", "run_solver", "compile_solver", "FitInterrupted", "STEP_AHEAD_VARIABLE",
    "step_ahead",
]

SOLVERS = ("lm", "gauss-newton", "bfgs")

# Tolerances on the O(1) unknowns and on the residual (in units of the target's
# contrast): far below any statistically meaningful change (a standard error is
# ~1e-3 relative at best). 1e-7 cost Levenberg-Marquardt 21 steps where 1e-5
# needs 12 for the same loss to 6 digits (experiments/bench_fit.py, 128 x 128).
RTOL = 1e-5
ATOL = 1e-5

# The multi-start solves only choose a basin; the winner is then solved again at
# RTOL/ATOL (robust rounds or a final refinement), so they stop at a looser
# tolerance. On data_synthetic/fran_front (0.5 % noise) 1e-3 moved the final
# estimate by under 0.05 standard errors and halved the steps of each start.
SCREEN_TOL = 1e-3

# Every solve of the estimator also stops once the Gauss-Newton step would move
# the unknowns by less than this many standard errors (run_solver's
# noise_tolerance). On data_synthetic/fran_front the two robust rounds spent 12
# and 7 steps moving log sss_level by 1.4e-3 (a fifth of its standard error) and
# then circling within 1e-4, where the passes' interpolation kinks make the loss
# rough: a tighter rtol there buys nothing a standard error can see.
NOISE_TOL = 0.05

# ... and once the loss has stalled: over the last STALL_WINDOW accepted steps,
# chi^2 (the loss over the noise variance, summed over the residual) fell by
# less than STALL_TOL. The Gauss-Newton prediction behind NOISE_TOL assumes a
# smooth loss; a model that misses the data (a path-traced or photographed
# target) has a rough one, where Levenberg-Marquardt creeps on with steps of a
# fraction of a standard error that each buy a few thousandths of chi^2. On the
# three path-traced pairs in data_synthetic/ this (with SCREEN_STALL_TOL for the
# starts) cut 561 steps to 330 and the fit time to 0.65; the estimates moved by
# at most 0.14 standard errors and every final loss came out equal or lower
# (experiments/bench_fit.py --stopping). Rejected steps do not count: a run of
# them is the trust region shrinking, after which the solve often moves on.
STALL_TOL = 0.1
STALL_WINDOW = 3

# The starts only choose a basin, so they stall at 1: two basins whose chi^2
# differ by less than that are ones the data cannot tell apart.
SCREEN_STALL_TOL = 1.0


#: The environment variable that sets :func:`step_ahead`: ``auto`` (default),
#: ``1`` or ``0``.
STEP_AHEAD_VARIABLE = "INVSSS_STEP_AHEAD"


def step_ahead() -> bool:
    """Whether :func:`run_solver` dispatches each step before reading the last one's loss.

    ``INVSSS_STEP_AHEAD`` = ``1`` or ``0`` decides; otherwise (``auto``) it steps
    ahead when JAX's default backend is not the CPU. On a GPU the host's work
    per step (dispatching the jitted step, reading its loss back, the callbacks)
    then overlaps the device's, instead of leaving the device idle for it
    (docs/gpu.md). On the CPU the device is the host's own cores, so there is
    nothing to overlap, and the one step each solve throws away would cost its
    full time.

    Raises
    ------
    InvalidInputError
        If ``INVSSS_STEP_AHEAD`` holds anything else.

    Examples
    --------
    >>> import jax
    >>> step_ahead() == (jax.default_backend() != "cpu"
    ...     and os.environ.get(STEP_AHEAD_VARIABLE, "auto") != "0")
    True
    """
    choice = os.environ.get(STEP_AHEAD_VARIABLE, "auto").strip().lower()
    if choice not in ("auto", "1", "0"):
        raise InvalidInputError(f"{STEP_AHEAD_VARIABLE}: expected one of auto, 1, 0, got {choice!r}",
                                field=STEP_AHEAD_VARIABLE)
    if choice == "auto":
        return jax.default_backend() != "cpu"
    return choice == "1"


class FitInterrupted(Exception):
    """A fit was asked to stop (its ``stop`` callable returned True) before any
    solver step finished, so there is no estimate to report."""


def make_solver(name: str, tolerance: float | None = None):
    """The optimistix solver called ``name`` (one of :data:`SOLVERS`).

    With ``tolerance`` its relative and absolute tolerances are that value held
    as arrays, which the jitted step traces: solvers that differ only in
    tolerance then share one compiled step. Without it, :data:`RTOL` and
    :data:`ATOL` as constants.

    Examples
    --------
    >>> make_solver("lm").rtol
    1e-05
    >>> print(f"{float(make_solver('bfgs', tolerance=1e-3).atol):.1e}")
    1.0e-03
    """
    rtol, atol = (RTOL, ATOL) if tolerance is None else (jax.device_put(np.asarray(tolerance)),) * 2
    if name == "lm":
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    if name == "gauss-newton":
        return optx.GaussNewton(rtol=rtol, atol=atol)
    if name == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol)
    raise InvalidInputError(f"solver: expected one of {', '.join(SOLVERS)}, got {name!r}", field="solver")


#: The Jacobians the solvers can be given: ``"forward-mode"`` (``jax.jacfwd``,
#: exact) or ``"differences"`` (the blur by forward differences; objectives with
#: a ``difference_jacobian`` method, such as the estimator's
#: :class:`~invsss.estimator.objective.Objective`).
JACOBIANS = ("forward-mode", "differences")

#: Step of the forward differences in the unknowns (logs, logits and scaled
#: offsets of order one). On data_synthetic/fran_front the columns then agree
#: with forward mode to 1e-3 for sss_level and 2e-5 or better for the others
#: (relative norm): what is left is the passes' linear interpolation, whose
#: slope jumps where a tap crosses a pixel centre.
DIFFERENCE_STEP = 1e-5


@eqx.filter_custom_jvp
def _residual(z, objective, differences):
    return objective(z)[0]


@_residual.def_jvp
def _residual_jvp(primals, tangents):
    z, objective, differences = primals
    tz = tangents[0]  # the data are never differentiated
    if differences:
        r, jac = objective.difference_jacobian(z, DIFFERENCE_STEP)
    else:
        jac, r = jax.jacfwd(lambda u: (objective(u)[0],) * 2, has_aux=True)(z)
    return r, (jnp.zeros_like(r) if tz is None else jac @ tz)


class DenseJacobian(eqx.Module):
    """The objective with a derivative rule that materialises the (N, n) Jacobian.

    Materialising it once per point means the solver's linearisation stores one
    small matrix instead of every intermediate of the blur passes, and a
    transposed product (BFGS's gradient) is a matrix product instead of reverse
    mode through gathers (scatters, slow on CPU). Measured at 64 x 64 (K = 5, three
    unknowns, a busy 2-core machine): 110 ms per Levenberg-Marquardt step before,
    6 ms after.

    ``differences`` (static): the objective's own ``difference_jacobian`` (the
    blur by forward differences, the grey mix exact, the projection in closed
    form) instead of ``jax.jacfwd`` throughout. Measured per Jacobian when the
    blur alone was differenced: 78 against 101 ms on data_synthetic/fran_front
    (224 x 224, five unknowns), 12 against 19 ms on pt_face_940 (128 x 128,
    three); the mix and the closed form then halved fran_front's (129-143 to
    66-74 ms on a slower machine). A solver needs no more accuracy than that
    (experiments/bench_fit.py --jacobian); the standard errors a fit reports
    come from forward mode (:mod:`.uncertainty`).
    """

    objective: eqx.Module
    differences: bool = eqx.field(static=True, default=False)

    def __call__(self, z, args=None):
        return _residual(z, self.objective, self.differences), None


class _HalfSumOfSquares(eqx.Module):
    """A least-squares residual as the scalar objective a minimiser needs."""

    residual: eqx.Module

    def __call__(self, z, args=None):
        r, _ = self.residual(z, args)
        return 0.5 * jnp.sum(r**2), None


def _as_fn(solver, objective, jacobian="forward-mode"):
    if jacobian not in JACOBIANS:
        raise InvalidInputError(f"jacobian: expected one of {', '.join(JACOBIANS)}, got {jacobian!r}")
    if jacobian == "differences" and not hasattr(objective, "difference_jacobian"):
        raise InvalidInputError(
            f"jacobian: 'differences' needs an objective with a difference_jacobian method "
            f"(invsss.estimator.objective.Objective), got {type(objective).__name__}"
        )
    fn = DenseJacobian(objective, jacobian == "differences")
    return _HalfSumOfSquares(fn) if isinstance(solver, optx.AbstractMinimiser) else fn


def _current_loss(state):
    # Gauss-Newton family: the residual at the last accepted point; BFGS: its value.
    info = state.f_info
    if hasattr(info, "residual"):
        return 0.5 * jnp.sum(info.residual**2)
    return info.f


_OPTIONS: dict = {}
_TAGS: frozenset = frozenset()


@persistent_jit
def _init(solver, fn, z):
    f_struct, aux_struct = jax.eval_shape(lambda: fn(z, None))
    return solver.init(fn, z, None, _OPTIONS, f_struct, aux_struct, _TAGS)


def _degrees_of_freedom(residual, n: int) -> jax.Array:
    """Nonzero residual entries (those the weights keep) less the ``n`` unknowns, at least 1."""
    return jnp.maximum(jnp.sum(residual != 0) - n, 1)


def gauss_newton_distance(residual, jacobian) -> jax.Array:
    """How far the Gauss-Newton step from this point moves the unknowns, in
    standard errors: the step's length in the metric of the covariance
    ``sigma^2 (J^T J)^-1`` the estimator reports, with ``sigma^2`` the residual's
    mean square over its nonzero entries (less one per unknown).

    It bounds the move of every unknown, and of any combination of them, in
    units of its standard error. Zero where the residual is zero.

    Examples
    --------
    One unknown moving the first residual: the step is 0.1 and the noise variance
    (0.01 + 0.01 + 0.04) / (3 - 1) = 0.03, so the step is 0.1 / sqrt(0.03) standard errors.

    >>> import jax.numpy as jnp
    >>> r = jnp.array([0.1, -0.1, 0.2, 0.0]); J = jnp.eye(4)[:, :1]
    >>> round(float(gauss_newton_distance(r, J)), 3)
    0.577
    """
    g = jacobian.T @ residual
    normal = jacobian.T @ jacobian
    # A tiny ridge keeps an undetermined direction from dividing by zero; such a
    # direction has no standard error to measure the step in anyway.
    ridge = 1e-12 * jnp.trace(normal) / normal.shape[0] + jnp.finfo(normal.dtype).tiny
    step = jnp.linalg.solve(normal + ridge * jnp.eye(normal.shape[0], dtype=normal.dtype), g)
    sigma2 = jnp.sum(residual**2) / _degrees_of_freedom(residual, normal.shape[0])
    return jnp.sqrt(jnp.maximum(g @ step, 0.0) / jnp.maximum(sigma2, jnp.finfo(sigma2.dtype).tiny))


@persistent_jit
def _step(solver, fn, z, state, noise_tolerance):
    z, state, _ = solver.step(fn, z, None, _OPTIONS, state, _TAGS)
    done, result = solver.terminate(fn, z, None, _OPTIONS, state, _TAGS)
    # f_info is the last accepted point's (the first step always accepts the start).
    info = state.f_info
    if noise_tolerance is not None:
        distance = gauss_newton_distance(info.residual, info.jac.as_matrix())
        done = done | (distance < noise_tolerance)
    # For the stall test; a minimiser's state has no residual (and no stall test).
    dof = _degrees_of_freedom(info.residual, z.size) if hasattr(info, "residual") else jnp.ones((), int)
    return z, state, _current_loss(state), dof, done, result == optx.RESULTS.successful


def stalled(accepted_losses, dof: int, tolerance: float, window: int = STALL_WINDOW) -> bool:
    """Whether chi^2 fell by less than ``tolerance`` over the last ``window`` accepted steps.

    ``accepted_losses`` are ``0.5 * sum(residual^2)`` at the accepted points, in
    order; chi^2 is the loss over the noise variance estimated from the residual
    (``sigma^2 = sum(residual^2) / dof``), so a fall ``d`` in the loss is
    ``d * dof / loss`` in chi^2: the relative change of the loss, in units of
    the noise.

    Examples
    --------
    A loss of 100 on 10 000 degrees of freedom: a fall of 0.0005 is 0.05 of chi^2.

    >>> stalled([100.001, 100.0007, 100.0006, 100.0005], 10_000, 0.1)
    True
    >>> stalled([100.01, 100.0007, 100.0006, 100.0005], 10_000, 0.1)
    False
    >>> stalled([100.0006, 100.0005], 10_000, 0.1)
    False
    """
    if len(accepted_losses) <= window:
        return False
    latest = accepted_losses[-1]
    return (accepted_losses[-1 - window] - latest) * dof < tolerance * latest


class SolveRecord(NamedTuple):
    """Outcome of one solve: final unknowns, ``0.5 sum rho^2`` per step, status
    (``failure`` says why a solve stopped unconverged before ``max_steps``;
    ``interrupted`` that ``stop`` ended it)."""

    z: jax.Array
    history: np.ndarray
    steps: int
    converged: bool
    failure: str = ""
    interrupted: bool = False
    state: object = None  # the solver's state after the last step: run_solver(state=) resumes there

    @property
    def final(self) -> float:
        return float(self.history[-1]) if len(self.history) else np.inf


def run_solver(
    solver,
    objective,
    z0,
    max_steps: int,
    on_step: Callable[[float], None] | None = None,
    stop: Callable[[], bool] | None = None,
    arrived: Callable[[jax.Array], bool] | None = None,
    noise_tolerance: float | None = None,
    stall_tolerance: float | None = None,
    jacobian: str = "forward-mode",
    state=None,
) -> SolveRecord:
    """Iterate ``solver`` from ``z0`` for at most ``max_steps`` steps.

    Parameters
    ----------
    solver : optimistix least-squares solver or minimiser
        E.g. from :func:`make_solver`.
    objective : equinox Module
        ``objective(z) -> (residual, aux)``; its arrays are traced, so objectives
        of one layout share the compiled step.
    z0 : array, shape (n,)
    max_steps : int
    on_step : callable, optional
        ``on_step(half_sum_of_squares)`` after every step.
    stop : callable, optional
        Polled after every step (after ``on_step``); True ends the solve with
        ``interrupted=True`` and ``converged=False`` at the last step's point.
    arrived : callable, optional
        ``arrived(z) -> bool``, the caller's own test of the point reached after
        each step (after ``stop``); True ends the solve there as converged (a
        multi-start fit ends a start that has entered a basin already solved).
    noise_tolerance : float, optional
        Least-squares solvers only: also converged once the Gauss-Newton step from
        the last accepted point would move the unknowns by less than this many
        standard errors (:func:`gauss_newton_distance`). Precision below the
        noise is bought with many steps that change nothing a standard error can
        see, and a model with kinks (the passes' linear interpolation) may never
        meet a tight ``rtol`` at all.
    stall_tolerance : float, optional
        Least-squares solvers only: also converged once chi^2 has fallen by less
        than this over the last :data:`STALL_WINDOW` accepted steps
        (:func:`stalled`); the test for a rough loss, where the Gauss-Newton
        prediction of the first test does not hold.
    jacobian : {"forward-mode", "differences"}
        How the solver's Jacobian is computed (:class:`DenseJacobian`).
    state : optional
        The ``state`` of an earlier record of the same solver, objective and
        Jacobian, whose ``z`` is then ``z0``: the solve goes on from there as if
        it had not stopped, instead of starting afresh at ``z0`` (a fresh start
        spends its first step evaluating the point that solve had already
        evaluated and accepted).

    Returns
    -------
    SolveRecord

    Examples
    --------
    >>> import equinox as eqx, jax.numpy as jnp, optimistix as optx
    >>> class Line(eqx.Module):
    ...     def __call__(self, z, args=None):
    ...         return jnp.array([z[0] - 1.0, 2.0 * (z[0] - 1.0)]), None
    >>> record = run_solver(optx.LevenbergMarquardt(1e-8, 1e-8), Line(), jnp.zeros(1), 50)
    >>> record.converged, round(float(record.z[0]), 6)
    (True, 1.0)
    >>> record = run_solver(optx.LevenbergMarquardt(1e-8, 1e-8), Line(), jnp.zeros(1), 50,
    ...                     stop=lambda: True)
    >>> record.steps, record.interrupted, record.converged
    (1, True, False)
    """
    fn = _as_fn(solver, objective, jacobian)
    noise_tolerance = _traced_tolerance(solver, noise_tolerance)
    if isinstance(solver, optx.AbstractMinimiser):
        stall_tolerance = None
    try:
        return _iterate(solver, fn, jnp.asarray(z0), max_steps, on_step, stop, arrived, noise_tolerance,
                        stall_tolerance, _init, _step, state)
    except StaleStatics:
        # The state came from a stored _init whose _step is not stored: solve
        # again from z0 with functions traced here (a state to resume is
        # dropped). This happens before the first step is reported, so the
        # caller sees one solve.
        return _iterate(solver, fn, jnp.asarray(z0), max_steps, on_step, stop, arrived, noise_tolerance,
                        stall_tolerance, _init.jitted, _step.jitted)


def _traced_tolerance(solver, noise_tolerance):
    """``noise_tolerance`` as :func:`_step` takes it: ``None`` for a minimiser
    (it has no residual to measure a step with), else an array, traced, so that
    every tolerance shares one compiled step."""
    if isinstance(solver, optx.AbstractMinimiser) or noise_tolerance is None:
        return None
    return jax.device_put(np.asarray(noise_tolerance, jnp.result_type(float)))


def compile_solver(
    solver, objective, z, noise_tolerance: float | None = None, jacobian: str = "forward-mode"
) -> None:
    """Compile (or load from the cache) the functions :func:`run_solver` will run
    for these arguments, without taking a step.

    The solver's ``init`` runs (it only sets up its state, a few milliseconds);
    its ``step`` is compiled for that state but not run. A :func:`run_solver` of
    an objective of the same layout (the same shapes and static parts; the
    values may differ) then compiles nothing. The estimator calls it on a
    second thread while the start scan runs, so the step compiles beside the
    scan's loss instead of after it.
    """
    fn = _as_fn(solver, objective, jacobian)
    z = jnp.asarray(z)
    state = _init(solver, fn, z)
    _step.prepare(solver, fn, z, state, _traced_tolerance(solver, noise_tolerance))


def _iterate(solver, fn, z, max_steps, on_step, stop, arrived, noise_tolerance, stall_tolerance,
             init, step, state=None) -> SolveRecord:
    if state is None:
        state = init(solver, fn, z)
    ahead = step_ahead()
    history: list = []
    accepted: list = []
    converged, failure, interrupted = False, "", False
    pending = step(solver, fn, z, state, noise_tolerance) if max_steps > 0 else None
    for i in range(max_steps):
        assert pending is not None  # set before the loop whenever max_steps > 0, and below
        z, state, loss, dof, done, ok = pending
        more = i + 1 < max_steps
        if ahead and more:
            # Dispatched before float(loss) waits for this step: the device
            # computes it meanwhile, and it is dropped if this step ends the solve.
            pending = step(solver, fn, z, state, noise_tolerance)
        loss = float(loss)
        history.append(loss)
        # The loss reported is the last accepted point's: a step that lowers it
        # was accepted (the first step accepts the start).
        if not accepted or loss < accepted[-1]:
            accepted.append(loss)
        if stall_tolerance is not None:
            done = bool(done) or stalled(accepted, int(dof), stall_tolerance)
        if on_step is not None:
            on_step(loss)
        if stop is not None and stop():
            interrupted = True
            break
        if not bool(ok):
            failure = "the solver's linear solve failed"
            break
        if bool(done) or (arrived is not None and arrived(z)):
            converged = True
            break
        if not np.isfinite(loss):
            failure = "the loss is not finite"
            break
        if more and not ahead:
            pending = step(solver, fn, z, state, noise_tolerance)
    return SolveRecord(z, np.asarray(history), len(history), converged, failure, interrupted, state)
