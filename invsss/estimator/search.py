"""The solve: starts, robust rounds and the active set, on a built problem.

:func:`solve_problem` takes a :class:`~.problem.FitProblem` and returns the
:class:`SolvePath` it reached: steps 3 and 4 of the fit
(:mod:`invsss.estimator.fit`). It knows nothing of the stages around it
(alignment, highlights, light terms, saturation): those call the whole fit.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import uncertainty
from .problem import evaluate
from .robust import psi_and_slope, robust_loss, robust_scale, robust_weights
from .solve import (
    NOISE_TOL,
    RTOL,
    SCREEN_STALL_TOL,
    SCREEN_TOL,
    STALL_TOL,
    FitInterrupted,
    make_solver,
    run_solver,
)
from .summary import entry_name
from .uncertainty import block_index

__all__ = ["SolvePath", "active_set", "choose_basin", "residuals_at", "solve_problem"]

_ROBUST_ROUNDS = 2

#: Steps every start takes before the starts are ranked and only the better half
#: go on (successive halving). On the seven bundled pairs this gave the same
#: estimates (within 0.07 standard errors) in 0.86-0.92 of the time: fran_front
#: 29 steps instead of 40, its four starts all reaching one basin.
HALVING_STEPS = 3
#: A start has entered a basin already solved when no unknown differs by more
#: than this from an earlier start's end point. The unknowns are O(1) (logs of
#: scales, logits of shares): 0.02 is 2 % of sss_level, a few of its standard
#: errors on a 224 x 224 face, well inside the basin the solver converges in.
#: The bottom of a basin is rough (the passes' linear interpolation has kinks),
#: so a start cut short can leave the fit in a neighbouring micro-minimum: on a
#: 64 x 64 face 0.25 standard errors from where walking every start ends, with a
#: loss the data cannot tell apart (chi^2 within 0.05).
SAME_BASIN = 0.02
#: Two fits are at different blur scales when their sss_level differ by more than
#: this (log ratio).
_DISTINCT_LEVEL = 0.1
#: Two basins whose robust losses differ by less than this many standard
#: deviations of the difference under the noise fit equally well: the fit says
#: so (see choose_basin).
AMBIGUOUS_Z = 2.0



class SolvePath:
    """The solve so far: objective (with its robust weights and active set), the
    unknowns and the last solve's status."""

    def __init__(self, objective, z):
        self.objective, self.z = objective, z
        self.converged, self.failure, self.interrupted = True, "", False
        self.messages: list[str] = []
        # (sss_level kept, [text per rival basin]): set by choose_basin, worded by
        # summary.rival_basin_warning once the standard errors are known.
        self.rival_basins: tuple[float, list[str]] | None = None
        self.delta = 0.0

    def extend(self, record):
        self.z = record.z
        self.converged, self.failure = record.converged, record.failure
        self.interrupted = record.interrupted


def solve_problem(problem, options, steps, before_first_step=None) -> SolvePath:
    """Multi-start, robust reweighting and the active set (steps 3 and 4 of
    :mod:`invsss.estimator.fit`).

    The starts stop at the looser :data:`~.solve.SCREEN_TOL` (they only pick the
    basin); with :attr:`~.problem.FitProblem.scan_after` the blur scale is then
    scanned around where the one start ended (:func:`_scan_after`). The best is
    solved again at the full tolerance, by the robust rounds or, without them,
    by a ``refine`` solve. Both solvers carry their tolerances as arrays, so
    they share one compiled step.
    Stops early, keeping the best point so far, when ``steps.stop`` asks.
    ``before_first_step()`` runs after the first poll of ``steps.stop`` (the fit
    waits there for its solver's compilation).
    """
    screen = make_solver(options.solver, tolerance=SCREEN_TOL)
    solver = make_solver(options.solver, tolerance=RTOL)
    path = SolvePath(problem.objective, problem.z_base)
    if not problem.param.size:
        return path
    # One poll before the first step: the start search can take a while, and
    # there is nothing to report yet.
    if steps.stop_requested():
        raise FitInterrupted("stop: the fit was interrupted before its first solver step")
    if before_first_step is not None:
        before_first_step()

    def run(on, label, z0, with_solver=solver, arrived=None, max_steps=None, state=None):
        # ``on``: the SolvePath whose objective (robust weights, active set) is solved.
        steps.begin(label)
        stall = (SCREEN_STALL_TOL if with_solver is screen else STALL_TOL) if options.stall_test else None
        return run_solver(with_solver, on.objective, z0, max_steps or options.max_steps, steps,
                          steps.stop_requested, arrived, NOISE_TOL, stall, options.solver_jacobian, state)

    best, records, interrupted = _starts(problem, options, functools.partial(run, path), screen)
    if problem.scan_after and not interrupted:
        best, interrupted = _scan_after(problem, functools.partial(run, path), screen, best, records)
    path.extend(best)
    path.interrupted = interrupted  # any start, not necessarily the best

    if options.robust is None or path.interrupted:
        if not path.interrupted:
            path.extend(run(path, "refine", path.z))
        active_set(problem, path, run)
        return path
    return _robust_rounds(problem, options, run, best, records)


def _starts(problem, options, run, screen):
    """Every start solved to the screening tolerance: the best record, all of them
    as ``(number, record)``, and whether a stop was asked for.

    Successive halving: every start first takes :data:`HALVING_STEPS` steps, and
    only the better half of them (by loss) goes on to the screening tolerance. A
    start that comes within :data:`SAME_BASIN` of a minimum an earlier start
    reached would only walk the rest of that start's way: it ends there.
    """
    best, minima, records = None, [], []
    interrupted = False

    def known_basin(z):
        return _near_any(z, minima)

    def finish(number, record):
        nonlocal best
        record = record._replace(state=None)  # a solver state holds the Jacobian: let it go
        minima.append(np.asarray(record.z))
        records.append((number, record))
        if best is None or record.final < best.final:
            best = record

    halving = len(problem.starts) > 2
    first = []
    for i, z0 in enumerate(problem.starts):
        if halving:
            record = run(f"start {i + 1}", z0, screen, None, min(HALVING_STEPS, options.max_steps))
            first.append((i + 1, record))
        else:
            record = run(f"start {i + 1}", z0, screen, known_basin)
            finish(i + 1, record)
        if record.interrupted:
            interrupted = True
            break
    if halving and interrupted:
        for number, record in first:
            finish(number, record)
    elif halving:
        ranked = sorted(first, key=lambda item: item[1].final)[: (len(first) + 1) // 2]
        if problem.nested and not any(item is first[0] for item in ranked):
            # The contained model's fit goes on whatever its first steps showed:
            # it is what makes the fit with the terms end at or below it.
            ranked.append(first[0])
        # Pop each start and clear the rest: an unfinished record holds its solver
        # state (the Jacobian among it), which should not outlive its use.
        first.clear()
        while ranked:
            number, record = ranked.pop(0)
            if not record.converged:
                # Resumed where the first round stopped, with the same solver and
                # objective: a fresh solve would spend a step on the point it left.
                record = run(f"start {number}, continued", record.z, screen, known_basin, state=record.state)
            finish(number, record)
            if record.interrupted:
                interrupted = True
                break
    return best, records, interrupted


def _scan_after(problem, run, screen, best, records):
    """The loss along the blur scale around where the one start's solve ended,
    and a solve from each of its local minima whose loss is already below that
    end's (at most ``n_starts``).

    A point of the scan changes the blur scale alone and leaves every other
    unknown (the light terms among them) where the start's solve ended, unsolved
    for the new blur; a loss below the end's therefore says that another basin
    holds a better fit than the one the start reached (a model-made dome lit
    with the law: the plain fit's estimate kept its blur 24 % wide, the scan
    found the dome's). Where the start's basin is the best, the fit pays for the
    scan's losses alone. Appends to ``records``; returns the best record and
    whether a stop was asked for.
    """
    end = np.asarray(best.z)
    here = problem.loss(end)
    minima = [np.asarray(r.z) for _, r in records]

    def known_basin(z):
        return _near_any(z, minima)

    lower = [z0 for z0, loss in problem.blur_minima(end) if loss < here and not known_basin(z0)]
    for z0 in lower[: problem.options.n_starts]:
        number = len(records) + 1
        record = run(f"start {number}", z0, screen, known_basin)._replace(state=None)
        minima.append(np.asarray(record.z))
        records.append((number, record))
        if record.final < best.final:
            best = record
        if record.interrupted:
            return best, True
    return best, False


def _near_any(z, minima) -> bool:
    """Whether ``z`` is within :data:`SAME_BASIN` of an end point already reached.

    NumPy, not jax.numpy: this runs on the host after every step.
    """
    z = np.asarray(z)
    return any(float(np.max(np.abs(z - m))) < SAME_BASIN for m in minima)


def _robust_rounds(problem, options, run, best, records) -> SolvePath:
    """Robust reweighting rounds, warm-started, then the active set.

    The starts were ranked under plain least squares with the weights' sign free;
    the robust loss with the sign imposed can rank two basins the other way (an
    8-bit JPEG of fran_front: least squares preferred sss_level 843 by 0.4 % of
    its loss, the robust loss preferred 600). So the best start of another basin
    is carried through the same rounds, and the two are compared on one robust
    objective (:func:`choose_basin`).
    """
    masks = [np.asarray(p.residual_weight) for p in problem.data]
    others = [(i, r) for i, r in sorted(records, key=lambda item: item[1].final)
              if not _near_any(r.z, [np.asarray(best.z)])]
    finished = []
    for number, record in [(None, best)] + others[:1]:
        path = SolvePath(problem.objective, record.z)
        path.extend(record)
        prefix = "" if number is None else f"start {number}, "
        for round_ in range(_ROBUST_ROUNDS):
            residual = residuals_at(problem, path)
            path.delta = robust_scale(residual, masks, options.robust)
            # device_put: jnp.asarray would compile a small copy for the new shape.
            u = tuple(jax.device_put(np.asarray(x)) for x in robust_weights(residual, path.delta, options.robust))
            path.objective = eqx.tree_at(lambda o: o.robust, path.objective, u)
            path.extend(run(path, f"{prefix}robust {round_ + 1}", path.z))
            if path.interrupted:
                break
        active_set(problem, path, run, prefix)
        finished.append(path)
        if path.interrupted:
            break
    if finished[-1].interrupted:
        # A stop asked for during a later candidate: report the first, as interrupted.
        finished[0].interrupted = True
        return finished[0]
    return choose_basin(problem, finished, options.robust) if len(finished) > 1 else finished[0]


def residuals_at(problem, path) -> list[np.ndarray]:
    """Each pair's target minus the prediction at ``path``'s point, (H, W, C')."""
    preds = evaluate(path.objective, path.z, np.asarray(False))["predictions"]
    return [np.asarray(p.target) - np.asarray(q) for p, q in zip(problem.data, preds)]


def choose_basin(problem, finished, robust):
    """The candidate with the lowest robust loss (one scale for all), with a warning
    when another one, at a different blur scale, fits as well within the noise.

    "As well": the difference of the two losses is less than
    :data:`AMBIGUOUS_Z` times its standard deviation under the noise. A change
    ``e`` of the target changes it by ``sum_i (psi_other - psi_best)_i e_i``;
    with ``e`` the kept fit's residual and the sum squared per block of
    :data:`~.uncertainty.BLOCK_PX` pixels (noise correlated within a block, as
    JPEG's is, counts as it should), that is the cluster-robust variance of
    :mod:`.uncertainty` applied to the loss difference.
    """
    masks = [np.asarray(p.residual_weight) for p in problem.data]
    delta = finished[0].delta

    def flat(images):
        return np.concatenate([np.asarray(x).ravel() for x in images])

    residuals = [residuals_at(problem, c) for c in finished]
    values = [robust_loss(r, masks, delta, robust) for r in residuals]
    best = int(np.argmin(values))
    chosen = finished[best]
    weight = flat([np.broadcast_to(np.asarray(m)[..., None], np.shape(r)) for m, r in zip(masks, residuals[best])])
    slopes = [weight * psi_and_slope(flat(r), delta, robust)[0] for r in residuals]
    blocks = block_index([np.shape(r) for r in residuals[best]], uncertainty.BLOCK_PX)
    level = float(problem.param.natural(np.asarray(chosen.z))["sss_level"])
    rivals = []
    for candidate, value, slope in zip(finished, values, slopes):
        other = float(problem.param.natural(np.asarray(candidate.z))["sss_level"])
        if abs(np.log(other / level)) <= _DISTINCT_LEVEL:
            continue
        by_block = np.bincount(blocks, weights=(slope - slopes[best]) * flat(residuals[best]))
        spread = float(np.sqrt(np.sum(by_block**2)))
        z = (value - values[best]) / spread if spread > 0 else np.inf
        if z < AMBIGUOUS_Z:
            rivals.append(f"{other:.4g} (loss higher by {z:.1f} standard deviations)")
    if rivals:
        chosen.rival_basins = (level, rivals)
    return chosen


def active_set(problem, path, run, prefix: str = "") -> None:
    """Weights are ratios on the simplex: hold negative ones at 0, re-solving
    after each change. An interrupted fit still gets this pass, without the
    re-solves (only the linear unknowns are projected again): its estimate must
    be a valid profile too, ready to render."""
    nb = int(path.objective.active.shape[0])
    if not problem.linear_weights or nb < 2:
        return
    for round_ in range(nb):
        coef = np.asarray(evaluate(path.objective, path.z, np.asarray(False))["coef"])
        active = np.asarray(path.objective.active)
        negative = (coef * np.sign(coef.sum(axis=0)) < 0) & (active > 0)
        if not negative.any():
            break
        held_out = jnp.asarray(np.where(negative, 0.0, active))
        path.objective = eqx.tree_at(lambda o: o.active, path.objective, held_out)
        if not path.interrupted:
            path.extend(run(path, f"{prefix}active set {round_ + 1}", path.z))
    held = np.asarray(path.objective.active) == 0
    held = held[:, 0] if problem.channels == 1 else held
    if held.any():
        names = ", ".join(entry_name("weights", i) for i in zip(*np.nonzero(held)))
        path.messages.append(f"{names}: held at 0 (the unconstrained least squares made them negative)")
