"""The fit's innermost stage and what every stage shares.

:class:`FitCall` is what a stage receives; :func:`core` is the stage inside all
others: build the problem (:func:`~.problem.build_problem`), solve it
(:func:`~.search.solve_problem`) and report (:func:`~.summary.summarise`).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable, Sequence

import jax
import numpy as np

from ..forward.params import PARAM_NAMES, SSSParams
from .canvas import crop
from .options import FitOptions
from .parametrisation import by_unknown
from .problem import build_problem
from .result import FitResult
from .search import solve_problem
from .solve import NOISE_TOL, SCREEN_TOL, compile_solver, make_solver
from .summary import mean_psnr, summarise

__all__ = ["Fit", "FitCall", "Solved", "Start", "Steps", "core", "estimate_of", "psnr_on_mask", "report"]


class Steps:
    """Every solver step of the fit, in the order taken: the loss history, the
    stage each step belongs to, the progress callback and the stop poll."""

    def __init__(self, progress, stop, to_loss):
        self.progress, self.stop, self.to_loss = progress, stop, to_loss
        self.losses: list[float] = []
        self.stages: list[tuple[str, int, int]] = []

    def begin(self, label: str) -> None:
        self.stages.append((label, len(self.losses), len(self.losses)))

    def __call__(self, half_sum_squares: float) -> None:
        self.losses.append(half_sum_squares * self.to_loss)
        label, first, _ = self.stages[-1]
        self.stages[-1] = (label, first, len(self.losses))
        if self.progress is not None:
            self.progress(len(self.losses), self.losses[-1])

    def stop_requested(self) -> bool:
        return self.stop is not None and bool(self.stop())


@dataclasses.dataclass(frozen=True)
class Start:
    """Where a fit starts: natural values of its free parameters.

    Attributes
    ----------
    values : dict
        Natural values (:func:`estimate_of` gives a fit's), as
        :func:`~.problem.build_problem` takes them.
    with_scan : bool
        False: the solve starts there instead of scanning (a neighbourhood known
        from an earlier fit of nearly the same pair). True: the scan runs and this
        start is kept among its best (a contained model's estimate, every added
        term at its identity, so the fit ends at or below that model's loss).
    scan_after : bool
        With ``with_scan`` False: once the solve from here has reached the
        screening tolerance, the scan runs around where it ended, and the fit
        also solves from any scanned point already below it
        (:func:`~.search.solve_problem`): another basin, at the cost of a scan
        where there is none.
    """

    values: dict
    with_scan: bool = False
    scan_after: bool = False


@dataclasses.dataclass(frozen=True)
class Solved:
    """A solved problem, before it is reported: what :func:`report` and the
    stages' reports read (the problem, its solve path and the steps taken)."""

    problem: object
    path: object
    steps: Steps
    single: bool


def report(solved: Solved, nuisance=None) -> FitResult:
    """The plain report of a solved problem (:func:`~.summary.summarise`).

    ``nuisance`` (an aligned fit's warp sensitivity) adds unknowns estimated
    outside the solve to the covariance. A stage that changes the report wraps
    the report it was given and passes ``nuisance`` on.
    """
    return summarise(solved.problem, solved.path, solved.single, solved.steps, nuisance)


@dataclasses.dataclass(frozen=True)
class FitCall:
    """One call of a fit stage: the pairs, the options and the run's callbacks.

    A stage (:mod:`.stages`) takes the stage inside it and returns a function of a
    ``FitCall``; it passes the call on changed (fewer pixels, another
    registration, a start, a report of its own) and never re-enters the whole fit.

    Attributes
    ----------
    pairs : sequence of (source, target, depth, mask) or ImagePair
    single : bool
        One pair (``fit_pair``): the report's per-pair arrays lose their first axis.
    options : FitOptions
    progress, stop : callable or None
        As for :func:`invsss.fit_pair`.
    start : Start or None
        Where the solve starts (:class:`Start`); None: the start scan alone.
    report : callable
        ``report(solved) -> FitResult``: how the solved problem becomes the
        result. :func:`report` by default; a stage that adds to the report (the
        warp's sensitivity, the light terms' comparison with the plain fit)
        wraps the one it was given.
    """

    pairs: Sequence
    single: bool
    options: FitOptions
    progress: Callable | None = None
    stop: Callable | None = None
    start: Start | None = None
    report: Callable[..., FitResult] = report


#: A fit stage's type: a FitCall in, a FitResult out.
Fit = Callable[[FitCall], FitResult]


def core(call: FitCall) -> FitResult:
    """The innermost stage: build the problem, solve it and report (steps 1-5 of
    :mod:`invsss.estimator.fit`), with every option the stages around it handle
    left to them."""
    options = call.options
    compiling = SolverCompilation(options)
    start = call.start
    problem = build_problem(call.pairs, options, None if start is None or start.with_scan else start.values,
                            compiling.start, nested=start.values if start is not None and start.with_scan else None,
                            scan_after=start is not None and start.scan_after)
    with jax.enable_x64(True):
        steps = Steps(call.progress, call.stop, problem.to_loss)
        path = solve_problem(problem, options, steps, compiling.wait)
        result = call.report(Solved(problem, path, steps, call.single))
    # Rebuild the parameters outside float64 mode: the caller gets arrays of their
    # own default precision, ready for render().
    # Host arrays on purpose (no compile), where SSSParams's fields are annotated as jax Arrays.
    params = SSSParams(*(np.asarray(result.values[k]) for k in PARAM_NAMES))  # type: ignore[arg-type]
    return dataclasses.replace(
        result, params=params, solver=options.solver, profile=options.profile_label,
        tap_weights=options.tap_label,
    )


def psnr_on_mask(problem, predictions) -> float:
    """PSNR over the pairs where the residual counted, at each pair's own size."""
    fitted = [crop(np.asarray(q), shape) for q, shape in zip(predictions, problem.shapes)]
    return mean_psnr(fitted, [np.asarray(p.target) for p in problem.given],
                      [np.asarray(p.residual_weight) for p in problem.given])


class SolverCompilation:
    """The solver's step compiled on a second thread while the start scan runs.

    A cold fit compiles two big functions: the loss the scan evaluates and the
    solver's step. The scan needs only the first, so the second compiles beside
    it (and beside the scan itself) rather than after it.

    On data_synthetic/fran_front (2 cores) the cold ``fit_pair`` went from 16.6
    to 13.7 s (medians of three runs alternating with the code before,
    experiments/bench_fit.py --breakdown). That is less than the step's 4.6 s
    of compilation: XLA's compilation keeps more than one core busy at times,
    and the two traces share the interpreter. The command line's cold fit
    gained less, within that machine's noise (medians 20.3 and 19.8 s); there
    the report's import shares the interpreter too. When the step is compiled
    already (a second fit in the process), the thread only sets up a solver
    state, a few milliseconds.

    ``start(problem)`` is :func:`build_problem`'s ``before_scan``. ``wait()``
    joins the thread before the first solve, so the two never compile the same
    function at once; a fit stopped before its first step does not wait. A
    failure on the thread is ignored: the solve then compiles the step itself
    and reports whatever is wrong.
    """

    def __init__(self, options: FitOptions):
        self.options = options
        self.thread: threading.Thread | None = None

    def start(self, problem) -> None:
        def compile_step():
            try:
                # float64 mode is a per-thread setting.
                with jax.enable_x64(True):
                    solver = make_solver(self.options.solver, tolerance=SCREEN_TOL)
                    # device_put, not jnp.asarray: that compiles a small copy for the shape.
                    z = jax.device_put(np.asarray(problem.z_base, np.float64))
                    compile_solver(solver, problem.objective, z, NOISE_TOL, self.options.solver_jacobian)
            except Exception:  # noqa: BLE001 - the solve compiles it again and says what is wrong
                pass

        # Not a daemon: a process that ends while XLA compiles on a daemon thread
        # (a fit interrupted during its scan) can abort in C++ as the interpreter
        # shuts down (seen: exit status -6 instead of 130). It waits instead.
        self.thread = threading.Thread(target=compile_step, name="invsss-compile-solver")
        self.thread.start()

    def wait(self) -> None:
        if self.thread is not None:
            self.thread.join()
            self.thread = None


def estimate_of(result) -> dict:
    """A fit's natural values, as :func:`build_problem` takes them for ``start``."""
    out = {k: result.values[k] for k in PARAM_NAMES}
    if result.mix is not None:
        out["mix"] = result.mix
    if result.vignetting is not None:
        out["vignetting"] = np.asarray(result.vignetting["coefficients"])
    if result.pigment is not None:
        out["pigment"] = np.asarray(result.pigment["estimate"])
    if result.light_terms is not None:
        out.update(by_unknown(result.light_terms))
    return out
