"""``fit_pair`` / ``fit_pairs``: estimate the model's parameters from image pairs.

The fit, step by step (each step its own module):

1. check the options (:class:`FitOptions`) and the inputs (:mod:`.inputs`);
   decide each parameter's role and the unknowns (:mod:`.parametrisation`);
2. scan the loss along the blur scale and start from its ``n_starts`` lowest
   local minima, each with the best correction and maxdd of a small grid
   (:mod:`.initial`). Steps 1 and 2 are :func:`build_problem`, public;
3. from each start, run the solver (:mod:`.solve`) on the residual with the linear
   unknowns projected out (:mod:`.objective`, :mod:`.projection`), to a looser
   tolerance; keep the best;
4. refine from the best at the full tolerance: robust reweighting rounds
   (:mod:`.robust`) or, without them, one more solve; then an
   active-set pass that holds at 0 any ``sog`` weight the unconstrained least
   squares makes negative (the weights are ratios on the simplex: a negative one
   is not a profile), re-solving after each change;
5. standard errors and undetermined parameters (:mod:`.uncertainty`), PSNR, SSIM
   and a misalignment check (:mod:`.diagnostics`), all in a :class:`FitResult`.

A ``stop`` callable, polled between solver steps, ends the fit early: the best
point reached so far is reported as usual, flagged ``interrupted``.

Everything runs in float64 (``jax.enable_x64`` inside the call): the projection's
normal equations over strongly correlated layers need it.
"""

from __future__ import annotations

import dataclasses
import threading

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import ndimage

from ..forward.light_terms import AFTER_BLUR, LightBuffers
from ..forward.pair import ImagePair
from ..forward.params import PARAM_NAMES, SSSParams
from ..validation import InvalidInputError
from .canvas import crop, frame_terms, unused_note
from .diagnostics import MISALIGNMENT_PX, masked_psnr, masked_ssim, misalignment
from .registration import Warp, align_source, align_target, align_vectors, estimate_warp, match_photometry
from .inputs import prepare_pairs
from .options import FitOptions
from .parametrisation import LIGHT_UNKNOWNS, by_unknown
from .problem import _evaluate, build_problem
from .result import FitResult, masked_list
from . import uncertainty
from .robust import psi_and_slope, robust_loss, robust_scale, robust_weights
from .solve import (
    NOISE_TOL, RTOL, SCREEN_STALL_TOL, SCREEN_TOL, STALL_TOL, FitInterrupted, compile_solver, make_solver,
    run_solver,
)
from .uncertainty import block_index, gauss_newton_uncertainty, structural_reasons
from .vignetting import vignetting_at

__all__ = ["fit_pair", "fit_pairs"]

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
#: so (see _choose_basin).
AMBIGUOUS_Z = 2.0

# The solvers' Jacobian (invsss.estimator.solve.DenseJacobian): the blur by forward
# differences, 0.64-0.77 of forward mode's time per step; the covariance uses
# forward mode.
SOLVER_JACOBIAN = "differences"


def fit_pair(
    source,
    target,
    depth,
    mask,
    *,
    model: str = "sog",
    profile="thesis-nir",
    fix: dict | None = None,
    gauge: str = "variances",
    solver: str = "lm",
    n_starts: int = 4,
    max_steps: int = 200,
    tap_weights=None,
    progress=None,
    robust: str | None = "pseudo-huber",
    align: str = "none",
    vignetting: bool = False,
    highlights: bool = False,
    saturation: float | None = None,
    light_terms=(),
    light_buffers=None,
    canvas=None,
    options: FitOptions | None = None,
    stop=None,
) -> FitResult:
    """Estimate the screen-space SSS parameters that turn ``source`` into ``target``.

    Minimises a robust masked residual between ``target`` and ``gain * out + offset``
    (``out`` the model applied to ``source``; docs/model.md, section 7) with the gains,
    offsets, RGB -> grey mix and, for ``sog``, the profile weights solved in closed
    form inside the residual (variable projection).

    Parameters
    ----------
    source : array, shape (H, W) or (H, W, C), C in {1, 3}
        Linear image without scattering.
    target : array, shape (H, W) or (H, W, C')
        The photograph to match: C' = C, or 1 for an RGB source (then a mix of the
        source channels is fitted too).
    depth : array, shape (H, W)
        Eye-space depth > 0 (mm recommended).
    mask : array, shape (H, W) or None
        Skin mask in [0, 1]; only masked pixels enter the fit (weighted by the mask).
        None uses every pixel.
    model : {"sog", "thesis", "separable"}
    profile : str, path, mapping or SumOfGaussians
        Sum-of-Gaussians profile: in the default gauge its variances are fixed; it
        also gives the number of Gaussians and the starting values.
    fix : dict, optional
        Parameters to hold at given values, e.g. ``{"maxdd": 0.01}`` or
        ``{"sss_level": 1200.0}``.
    gauge : {"variances", "sss_level"}
        Which side of the ``L`` / variance-scale degeneracy is fixed: the profile's
        variances (default), or ``sss_level`` (must be given in ``fix``; the
        variances are then estimated).
    solver : {"lm", "gauss-newton", "bfgs"}
    n_starts : int
        Number of starting points (best grid points of a coarse search).
    max_steps : int
        Maximum solver steps per start and per refinement.
    tap_weights : {"jimenez", "thesis"} or 7 numbers, optional
        Default "thesis" for the thesis model, else "jimenez".
    progress : callable, optional
        Called as ``progress(iteration, loss)`` after every solver step;
        ``iteration`` counts the steps of the whole fit (all starts and
        refinements) from 1, ``loss`` is in the units of :attr:`FitResult.loss`;
        the last ``iteration`` is :attr:`FitResult.iterations` and the losses are
        :attr:`FitResult.history`.
    robust : {"pseudo-huber", "cauchy"} or None
        Robust loss by iterative reweighting (see :mod:`invsss.estimator.robust`).
    align : {"none", "translation", "similarity", "affine"}
        Register the pair as part of the fit, for photographs that are not
        pixel-aligned with their render. The warp (source pixels to target pixels)
        is estimated against the photometrically matched source; the source, depth
        and mask are resampled onto the target's grid (the noisy target never is:
        see :mod:`invsss.estimator.registration`) and fitted; the warp is refined against
        that fit's prediction (which carries the blur, so the blur does not bias
        the warp), alternating (at most 4 rounds, each a one-start fit of at most
        30 steps per solve from the previous round's estimate) until the warp
        moves less than 0.01 px, and the pair fitted again. The warp is in
        :attr:`FitResult.alignment` and the fitted images are on the target's grid.
        The standard errors count the warp as estimated too (its parameters join the
        covariance as nuisance unknowns; their own standard errors are in the
        alignment record). Target pixels that come from
        outside the source's frame leave the mask. Two to five times the time of a fit.
    vignetting : bool
        Fit the camera's fall-off toward the corners as a gain field
        ``1 + a_1 rho^2 + a_2 rho^4`` about the frame's centre
        (:mod:`invsss.estimator.vignetting`), for photographs; reported in
        :attr:`FitResult.vignetting`, and the standard errors account for it.
    highlights : bool
        Leave specular highlights out: after the fit, pixels where the target is
        brighter than the prediction by more than :data:`HIGHLIGHT_SIGMAS` robust
        standard deviations of the residual (smoothed over 1 px; dilated by 1 px)
        are excluded from the comparison and the pair is fitted again. Reported in
        :attr:`FitResult.highlights`.
    saturation : float, optional
        The target's clipping level (in the target's units, e.g. the decoded value
        of an 8-bit file's code 255): masked pixels with any channel at or above it
        are left out of the comparison, and their count is in
        :attr:`FitResult.warnings`. A clipped pixel reads darker than the light that
        reached it; about a hundred of them (0.4 % of a face) moved a photograph's
        fit to a basin with sss_level 50 % high.
    light_terms : sequence of {"shift", "grazing", "incidence", "law"}, or a mapping
        Add the light-aware terms of docs/model.md, section 8, to the blur: a
        shift of the scattered light away from the light (``kappa``, mm), a
        gain towards grazing view (``gamma``), a gain towards grazing
        incidence of the key light (``beta``), and a multiple-scattering
        reflectance law for the key light's part of the source (``w``, an
        albedo in (0, 1) per source channel). Names are fitted; a mapping
        ``{"shift": 1.3, "grazing": None}`` holds a term at a value (a value
        measured on a registered pair, for an aligned fit of a photograph) and
        fits one given None. Each needs its buffers in ``light_buffers``;
        reported in :attr:`FitResult.light_terms`.
    light_buffers : LightBuffers, optional
        Camera-space ``light`` (unit vectors towards the key light) and ``normal``
        buffers of shape (H, W, 3), and ``key`` (the source lit by the key light
        alone, the source's shape), on the source's grid.
    canvas : (int, int), optional
        Fit on a (height, width) canvas at least the pair's size: pairs of
        different sizes fitted on one canvas share one compilation (a sweep, a
        loop over photographs), and the estimate is the one at the pair's own
        size. The pair is padded outside its mask; where the mask reaches its
        last row or column, or with ``vignetting``, ``light_terms`` or ``align``,
        it is fitted at its own size and the result warns
        (:mod:`invsss.estimator.canvas`).
    options : FitOptions, optional
        All of the above options (``model`` to ``canvas``) in one checked value;
        then leave those keywords at their defaults.
    stop : callable, optional
        ``stop() -> bool``, polled after every solver step (and once before the
        first): True ends the fit there, skipping the remaining starts and
        refinements, and the best point reached is reported with
        ``interrupted=True`` and ``converged=False``.

    Returns
    -------
    FitResult

    Raises
    ------
    InvalidInputError
        Bad shapes, NaN values, non-positive depth, empty mask, unknown model, solver,
        gauge or robust loss, a ``fix`` entry with an unknown name or a bad value,
        ``gauge="sss_level"`` without ``fix["sss_level"]``.
    FitInterrupted
        ``stop()`` returned True before any solver step finished.

    Examples
    --------
    >>> import numpy as np, invsss
    >>> rng = np.random.default_rng(0)
    >>> source = rng.uniform(0.2, 1.0, (24, 24))
    >>> depth = np.full((24, 24), 500.0); mask = np.ones((24, 24))
    >>> truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    >>> target = np.asarray(invsss.render(source, depth, mask, truth))
    >>> fit = invsss.fit_pair(source, target, depth, mask, profile={"weights": [0.5, 0.5],
    ...                       "variances": [0.5, 2.0]}, fix={"correction": 0.0, "maxdd": 1.0})
    >>> round(float(fit.params.sss_level))
    600
    """
    given = dict(model=model, profile=profile, fix=fix, gauge=gauge, solver=solver, n_starts=n_starts,
                 max_steps=max_steps, tap_weights=tap_weights, robust=robust, align=align,
                 vignetting=vignetting, highlights=highlights, saturation=saturation, light_terms=light_terms,
                 canvas=canvas)
    if light_buffers is None:
        pair = (source, target, depth, mask)
    elif isinstance(light_buffers, LightBuffers):
        pair = ImagePair(source, target, depth, mask, normal=light_buffers.normal, light=light_buffers.light,
                         key=light_buffers.key)
    else:
        raise InvalidInputError(f"light_buffers: expected an invsss.LightBuffers, got {type(light_buffers).__name__}")
    return _fit([pair], True, _options(options, given), progress, stop)


def fit_pairs(
    pairs,
    *,
    model: str = "sog",
    profile="thesis-nir",
    fix: dict | None = None,
    gauge: str = "variances",
    solver: str = "lm",
    n_starts: int = 4,
    max_steps: int = 200,
    tap_weights=None,
    progress=None,
    robust: str | None = "pseudo-huber",
    align: str = "none",
    vignetting: bool = False,
    highlights: bool = False,
    saturation: float | None = None,
    light_terms=(),
    canvas=None,
    options: FitOptions | None = None,
    stop=None,
) -> FitResult:
    """Fit one set of parameters to several pairs (see :func:`fit_pair`).

    ``pairs`` is a sequence of ``(source, target, depth, mask)`` tuples or
    :class:`invsss.ImagePair` objects, all with the same channel layout (sizes may
    differ). The SSS parameters, weights and the RGB -> grey mix are shared; each
    pair has its own offset and gain (the exposure may differ), per target channel.
    ``FitResult.gain`` and ``offset`` then have shape (P, C'). ``options`` and
    ``stop`` as for :func:`fit_pair`.
    """
    given = dict(model=model, profile=profile, fix=fix, gauge=gauge, solver=solver, n_starts=n_starts,
                 max_steps=max_steps, tap_weights=tap_weights, robust=robust, align=align,
                 vignetting=vignetting, highlights=highlights, saturation=saturation, light_terms=light_terms,
                 canvas=canvas)
    return _fit(pairs, False, _options(options, given), progress, stop)


# ----------------------------------------------------------------- jitted pieces


# ----------------------------------------------------------------- the fit


class _Steps:
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


def _entry(name, index) -> str:
    """``"weights[2]"`` or ``"weights[2,0]"`` for an entry of an array parameter."""
    return f"{name}[{','.join(str(int(i)) for i in index)}]"


def _check_callback(name, value):
    if value is not None and not callable(value):
        raise InvalidInputError(f"{name}: expected a callable or None, got {type(value).__name__}")


def _options(options, given):
    """``options`` if given (then the keywords must be left at their defaults),
    else a FitOptions from the keywords."""
    if options is None:
        return FitOptions(**given)
    if not isinstance(options, FitOptions):
        raise InvalidInputError(f"options: expected a FitOptions, got {type(options).__name__}")
    defaults = FitOptions.__dataclass_fields__
    changed = [
        name for name, value in given.items()
        if value is not defaults[name].default
        and not (isinstance(value, (str, int)) and value == defaults[name].default)
    ]
    if changed:
        raise InvalidInputError(
            f"options: give either options= or keyword options, not both (got {', '.join(changed)})"
        )
    return options


def _fit(pairs, single, options, progress, stop, nuisance=None, start=None) -> FitResult:
    """The fit; ``nuisance`` (an aligned fit's :class:`_WarpSensitivity`) adds
    unknowns estimated outside the solve to the covariance of the final fit;
    ``start`` (natural values, see :func:`build_problem`) replaces the start scan."""
    _check_callback("progress", progress)
    _check_callback("stop", stop)
    if options.saturation is not None:
        return _fit_unsaturated(pairs, single, options, progress, stop)
    if options.align != "none":
        return _fit_aligned(pairs, single, options, progress, stop)
    plain = None
    if options.light_terms and start is None:
        # The terms nest the plain model (each has a value that is the identity):
        # fit the plain model first and give its estimate, every term at its
        # identity, to the fit with the terms as a start it cannot end above.
        plain = _fit(pairs, single, _without_light_terms(options), progress, stop, nuisance)
        if plain.interrupted:
            return plain
    compiling = _SolverCompilation(options)
    nested = None if plain is None else {**_estimate(plain), **_IDENTITY}
    problem = build_problem(pairs, options, start, compiling.start, nested=nested)
    with jax.enable_x64(True):
        steps = _Steps(progress, stop, problem.to_loss)
        path = _solve(problem, options, steps, compiling.wait)
        result = _report(problem, path, single, steps, nuisance)
        if plain is not None:
            result = _against_plain(problem, path, result, plain)
    # Rebuild the parameters outside float64 mode: the caller gets arrays of their
    # own default precision, ready for render().
    params = SSSParams(*(np.asarray(result.values[k]) for k in PARAM_NAMES))  # host arrays: no compile
    result = dataclasses.replace(
        result, params=params, solver=options.solver, profile=options.profile_label,
        tap_weights=options.tap_label,
    )
    if options.highlights and not result.interrupted:
        return _fit_without_highlights(problem.given, result, single, options, progress, stop, nuisance)
    return result


#: Every light term's unknown at its identity (docs/model.md, section 8): no
#: shift, no gain, the law at strength 0 (its albedo then does nothing).
_IDENTITY = {"light_shift": 0.0, "grazing": 0.0, "incidence": 0.0, "law_strength": 0.0}
#: A term set that scores this much (dB) below the plain fit on the fit's own
#: mask is not kept: the plain fit is returned, with every term at its identity.
WORSE_THAN_PLAIN_DB = 0.0
#: A term that adds less than this (dB) to the fit's PSNR, measured by setting it
#: to its identity in the final fit, is reported as not describing the pair.
NEGLIGIBLE_DB = 0.05


def _without_light_terms(options: FitOptions) -> FitOptions:
    """The plain model's options: no light terms; highlights are left to the caller's
    own refit, which starts its plain fit again on the pairs it keeps."""
    return dataclasses.replace(options, light_terms=(), light_fixed={}, highlights=False)


def _mean_psnr(fitted, targets, masks) -> float:
    """PSNR of every pair on its mask, averaged with the masks' sizes as weights."""
    size = np.array([m.sum() for m in masks])
    return float(np.average([masked_psnr(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=size))


def _psnr(problem, predictions) -> float:
    """PSNR over the pairs where the residual counted, at each pair's own size."""
    fitted = [crop(np.asarray(q), shape) for q, shape in zip(predictions, problem.shapes)]
    return _mean_psnr(fitted, [np.asarray(p.target) for p in problem.given],
                      [np.asarray(p.residual_weight) for p in problem.given])


def _against_plain(problem, path, result, plain) -> FitResult:
    """Measure what each term adds to the plain fit (``psnr_plain``, ``psnr_without``
    in the terms' record), warn about terms that did not help, and fall back to the
    plain fit when the terms together scored below it."""
    record = dict(result.light_terms)
    layout = problem.param.layout()
    without = {}
    for term, name in LIGHT_UNKNOWNS.items():
        if term == "law_strength" or term not in record:
            continue
        knocked = "law_strength" if term == "law" else name
        if knocked not in layout:
            continue  # a held term: its value is the user's
        first, stop = layout[knocked]
        z = np.asarray(path.z, np.float64).copy()
        z[first:stop] = 0.0
        predictions = _evaluate(path.objective, jax.device_put(z), np.asarray(False))["predictions"]
        without[term] = _psnr(problem, predictions)
    record["psnr_plain"] = plain.psnr
    record["psnr_without"] = without
    messages = list(result.warnings)
    if result.psnr < plain.psnr - WORSE_THAN_PLAIN_DB and not result.interrupted:
        held = {term: 0.0 for term in AFTER_BLUR if term in record}
        if "law" in record:
            held["law_strength"] = 0.0
        identity = {**record, **held, "psnr_without": {}, "fallback": True}
        identity["stderr"] = {term: None for term in record["stderr"]}
        message = (
            f"light_terms: the fit with {', '.join(sorted(without) or record)} scored "
            f"{plain.psnr - result.psnr:.2g} dB below the plain fit ({result.psnr:.2f} against "
            f"{plain.psnr:.2f} dB): the terms do not describe this pair, and the plain fit is returned, "
            "every term at its identity"
        )
        return dataclasses.replace(plain, light_terms=identity, warnings=(*plain.warnings, message))
    messages.extend(_term_bounds(record))
    for term, value in without.items():
        if result.psnr - value < NEGLIGIBLE_DB:
            messages.append(
                f"light_terms.{term}: adds {result.psnr - value:+.3f} dB to the fit (PSNR {result.psnr:.2f} dB "
                f"with it, {value:.2f} dB with it at its identity): it does not describe this pair; leave it out"
            )
    return dataclasses.replace(result, light_terms=record, warnings=tuple(messages))


#: The law's albedo this close to 0 or 1 is at the edge of its range: the
#: sigmoid that maps it flattens, and the fit pushes on it because the law does
#: not describe the data (an unseen face ended at 0.99993 with the law making
#: the fit 12 dB worse).
ALBEDO_EDGE = 1e-3
#: A gain term this close to -1 darkens to nothing.
GAIN_EDGE = 0.99


def _term_bounds(record) -> list[str]:
    """Warnings for light-term values at the edge of their range."""
    out = []
    if "law" in record and "law" not in record["fixed"]:
        w = np.atleast_1d(np.asarray(record["law"], np.float64))
        edge = (w < ALBEDO_EDGE) | (w > 1.0 - ALBEDO_EDGE)
        if edge.any():
            out.append(
                f"light_terms.law: the albedo ended at {'/'.join(f'{x:.5g}' for x in w)}, at the edge of (0, 1): "
                "the law does not describe this pair there, and its standard error is not meaningful"
            )
    if "law_strength" in record:
        a = float(record["law_strength"])
        err = record["stderr"].get("law_strength")
        margin = 2.0 * err if err is not None else 0.0
        if a < -margin or a > 1.0 + margin:
            out.append(
                f"light_terms.law_strength: {a:.3g} is outside [0, 1] (by more than two standard errors): "
                "the fit extrapolates the blend of Lambert's and the law's reflection, which no medium does"
            )
    for term in ("grazing", "incidence"):
        if term in record and term not in record["fixed"] and float(record[term]) <= -GAIN_EDGE:
            out.append(f"light_terms.{term}: {float(record[term]):.4g} is at its bound -1 (a gain near 0)")
    return out


class _SolverCompilation:
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
                    compile_solver(solver, problem.objective, z, NOISE_TOL, SOLVER_JACOBIAN)
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


#: A pixel is a highlight when its residual, smoothed over 1 px, is brighter than
#: the prediction by this many robust standard deviations of the smoothed residual.
HIGHLIGHT_SIGMAS = 3.0


def _highlight_map(target, fitted, region) -> np.ndarray:
    """Pixels (H, W) of ``region`` where the target is markedly brighter than the fit."""
    residual = np.asarray(target, np.float64) - np.asarray(fitted, np.float64).reshape(np.shape(target))
    smooth = ndimage.gaussian_filter(residual.mean(axis=-1), 1.0)
    values = smooth[region]
    spread = 1.4826 * float(np.median(np.abs(values - np.median(values))))
    bright = region & (smooth - np.median(values) > HIGHLIGHT_SIGMAS * spread)
    return ndimage.binary_dilation(bright, iterations=1) & region


def _fit_unsaturated(pairs, single, options, progress, stop) -> FitResult:
    """The fit with each target's clipped pixels (``saturation``) left out."""
    prepared = prepare_pairs(pairs)
    out, messages = [], []
    for i, pair in enumerate(prepared):
        clipped = np.any(np.asarray(pair.target) >= options.saturation, axis=-1) & (np.asarray(pair.mask) > 0)
        count = int(clipped.sum())
        keep = np.where(clipped, 0.0, 1.0 if pair.fit_weight is None else np.asarray(pair.fit_weight))
        if count:
            name = f"pairs[{i}].target" if len(prepared) > 1 else "target"
            if not (keep * np.asarray(pair.mask)).any():
                raise InvalidInputError(f"{name}: every masked pixel is at or above the saturation level "
                                        f"{options.saturation:g}")
            messages.append(f"{name}: {count} masked pixel(s) at or above the saturation level "
                            f"{options.saturation:g} (clipped) left out of the fit")
        out.append(dataclasses.replace(pair, fit_weight=keep if count else pair.fit_weight))
    result = _fit(out, single, dataclasses.replace(options, saturation=None), progress, stop)
    return dataclasses.replace(result, warnings=tuple(messages) + tuple(result.warnings))


def _fit_without_highlights(data, first, single, options, progress, stop, nuisance=None) -> FitResult:
    """Refit with the specular highlights of the first fit's residual left out (``highlights``)."""
    pairs, counts, fractions = [], [], []
    for pair, fitted in zip(data, first.fitted):
        region = np.asarray(pair.residual_weight) > 0
        bright = _highlight_map(pair.target, fitted, region)
        counts.append(int(bright.sum()))
        fractions.append(counts[-1] / max(float(region.sum()), 1.0))
        keep = np.where(bright, 0.0, 1.0 if pair.fit_weight is None else np.asarray(pair.fit_weight))
        pairs.append(dataclasses.replace(pair, fit_weight=keep if (keep * np.asarray(pair.mask)).any() else None))
    record = {
        "method": f"residual of a first fit smoothed over 1 px, brighter than the prediction by "
                  f"{HIGHLIGHT_SIGMAS:g} robust standard deviations, dilated by 1 px",
        "excluded_pixels": counts,
        "fraction": fractions,
    }
    if not any(counts):
        return dataclasses.replace(first, highlights=record)
    second = _fit(pairs, single, dataclasses.replace(options, highlights=False), progress, stop, nuisance)
    return dataclasses.replace(second, highlights=record)


def _fit_aligned(pairs, single, options, progress, stop) -> FitResult:
    """A fit with the source side registered onto the target (``align``; see :func:`fit_pair`)."""
    from ..forward.screen_space import render

    prepared = prepare_pairs(pairs)
    checked = [
        (np.asarray(p.source, np.float64), np.asarray(p.target, np.float64), np.asarray(p.depth, np.float64),
         np.asarray(p.mask, np.float64), p.target_ndim)
        for p in prepared
    ]
    # The warp's sensitivity resamples the pairs at their own sizes: no canvas
    # (the warning says so; see .canvas).
    plain = dataclasses.replace(options, align="none", canvas=None)

    def aligned(warps):
        out = []
        for (source, target, depth, mask, ndim), warp, pair in zip(checked, warps, prepared):
            moved, moved_depth, kept = align_source(source, depth, mask, warp, target.shape[:2])
            if not (kept > 0).any():
                raise InvalidInputError("align: the registered source does not overlap the target")
            # The rim of the resampled mask is where the resampling is least like the
            # camera's own view (the mask and depth jump there): leave it out of the
            # comparison, not out of the model.
            inner = ndimage.binary_erosion(kept > 0, iterations=ALIGN_RIM_PX).astype(np.float64)
            if pair.fit_weight is not None:
                # The comparison is on the target's grid, and so is a fit weight
                # (the clipped pixels of saturation=, for one).
                inner = inner * np.asarray(pair.fit_weight)
            if not inner.any():
                inner = None
            # The key light's part of the source moves with the source.
            key = None if pair.key is None else align_source(pair.key, depth, mask, warp, target.shape[:2])[0]
            out.append(ImagePair(moved, target[..., 0] if ndim == 2 else target, moved_depth, kept,
                                 fit_weight=inner, normal=align_vectors(pair.normal, warp, target.shape[:2]),
                                 light=align_vectors(pair.light, warp, target.shape[:2]), key=key))
        return out

    warps = [estimate_warp(target, match_photometry(source, target, mask), mask, options.align)
             for source, target, _, mask, _ in checked]
    # Fits on the current registration give parameters whose prediction carries the
    # blur; registering against that removes the blur's pull on the warp. The two
    # depend on each other, so alternate until the warp settles: a warp off by a
    # tenth of a pixel at the face's edge moves sss_level by tens of per cent.
    previous = None
    for _ in range(ALIGN_ROUNDS):
        # After the first round the warp moves by a fraction of a pixel: start from
        # the last round's estimate instead of scanning again.
        rough = dataclasses.replace(plain, n_starts=1, highlights=False,
                                    max_steps=min(plain.max_steps, ALIGN_ROUND_STEPS))
        trial = _fit(aligned(warps), single, rough, progress, stop, start=previous)
        previous = _estimate(trial)
        if trial.interrupted:
            return dataclasses.replace(trial, alignment=tuple(w.to_dict() for w in warps))
        refined = []
        for (source, target, depth, mask, _), warp, pair in zip(checked, warps, prepared):
            # The whole model, light terms included: a prediction without the
            # shift would leave it for the warp to take.
            lit = {} if trial.light_terms is None else {
                "light_terms": trial.light_terms_params(),
                "light_buffers": pair.light_buffers}
            prediction = np.asarray(render(source, depth, mask, trial.params, options.model,
                                           tap_weights=options.tap_weights, **lit), np.float64)
            prediction = prediction[..., None] if prediction.ndim == 2 else prediction
            if trial.vignetting is not None:
                # Shaded as the photograph is, where the warp puts each source pixel: an
                # unshaded prediction leaves the fall-off to the warp's scale (20 % at
                # the corners of fran_front read as a scale of 0.999, which moved
                # correction by +7 %).
                rows, cols = np.mgrid[0:mask.shape[0], 0:mask.shape[1]]
                at = warp.map_points(np.stack([rows.ravel(), cols.ravel()], axis=1))
                shade = vignetting_at(trial.vignetting["coefficients"], at, target.shape[:2])
                prediction = prediction * shade.reshape(mask.shape)[..., None]
            # The prediction in the target's channels (gain, offset, RGB -> grey mix),
            # matched against the current registration of the target.
            reference = match_photometry(prediction, align_target(target, mask, warp)[0], mask)
            refined.append(estimate_warp(target, reference, mask, options.align, start=warp))
        moved = max(_warp_change(a, b, mask) for a, b, (_, _, _, mask, _) in zip(warps, refined, checked))
        warps = refined
        if moved < ALIGN_SETTLED_PX:
            break
    sensitivity = _WarpSensitivity(checked, warps)
    result = _fit(aligned(warps), single, plain, progress, stop, sensitivity)
    # How far the warp moves the mask's corners from where they were: zero parameters are the identity.
    resampled = max(_warp_change(w, Warp(w.kind, (0.0,) * len(w.params), w.centre), mask)
                    for w, (_, _, _, mask, _) in zip(warps, checked))
    messages = result.warnings
    if options.canvas is not None:
        messages += (unused_note(frame_terms(options)),)
    if resampled > ALIGN_SETTLED_PX:
        messages += (
            f"align: the source was resampled onto the photograph's grid (the warp moves it by up to "
            f"{resampled:.2f} px); that alone biases sss_level by a few per cent beyond its standard "
            "error (-3 to -5 % on a model-made face). "
            "For final numbers render the source again from the camera the warp implies (invsss scene "
            "--warp params.json --source-only, for a scene invsss renders) and fit that with align again",
        )
    if "shift" in options.light_terms and "shift" not in options.light_fixed:
        messages += (
            "light_terms: the shift term moves the image along the light's direction, and where that "
            "direction varies little over the mask so does a translation of the warp: one pair cannot "
            "tell them apart, and the split between the fitted shift and the warp is not determined "
            "(measure the shift on a pair whose registration is known)",
        )
    elif "shift" in options.light_terms:
        messages += (
            "light_terms: with the shift held, the registration rounds see it but converge slowly (on a "
            "model-made card 4 rounds left the warp 0.3 px off and sss_level 34 % low); check the warp "
            "in report.png",
        )
    return dataclasses.replace(result, alignment=sensitivity.records(), warnings=messages)


def _estimate(result) -> dict:
    """A fit's natural values, as :func:`build_problem` takes them for ``start``."""
    out = {k: result.values[k] for k in PARAM_NAMES}
    if result.mix is not None:
        out["mix"] = result.mix
    if result.vignetting is not None:
        out["vignetting"] = np.asarray(result.vignetting["coefficients"])
    if result.light_terms is not None:
        out.update(by_unknown(result.light_terms))
    return out


#: The warp's parameters are perturbed by steps that move the mask's farthest
#: corner this far (px) to differentiate the residual: below the 0.1 px that
#: moves the blur estimate, above the resampling's rounding.
WARP_STEP_PX = 0.05


@eqx.filter_jit
def _explicit_residual(objective, z, coef, offset):
    return objective.explicit_residual(z, coef, offset)


class _WarpSensitivity:
    """How the final fit's residual changes with each warp parameter, so that the
    standard errors count the warp as estimated (:func:`gauss_newton_uncertainty`'s
    ``nuisance``), and the warps with their own standard errors for params.json.

    The derivative is a central difference of the whole resampling (source,
    depth and mask moved by :func:`~invsss.estimator.registration.align_source`) with the
    scattering parameters, the linear unknowns and the residual's weights held.
    The fit's report calls :meth:`columns` and stores the warp parameters'
    standard errors in ``stderr``, which :meth:`records` then writes out.
    """

    def __init__(self, checked, warps):
        self.checked, self.warps = checked, warps
        self.stderr = None

    def _steps(self, warp, mask) -> np.ndarray:
        reach = float(np.max(np.linalg.norm(_corners(mask) - np.asarray(warp.centre), axis=1)))
        steps = np.full(len(warp.params), WARP_STEP_PX / max(reach, 1.0))
        steps[:2] = WARP_STEP_PX  # the shift is in pixels already
        return steps

    def columns(self, objective, z, coef, offset) -> np.ndarray:
        out = []
        for i, ((source, target, depth, mask, _), warp) in enumerate(zip(self.checked, self.warps)):
            for j, h in enumerate(self._steps(warp, mask)):
                sides = []
                for sign in (1.0, -1.0):
                    params = np.array(warp.params, np.float64)
                    params[j] += sign * h
                    moved, moved_depth, kept = align_source(
                        source, depth, mask, Warp(warp.kind, tuple(params), warp.centre), target.shape[:2])
                    shifted = eqx.tree_at(
                        lambda o: (o.pairs[i].source, o.pairs[i].depth, o.pairs[i].mask), objective,
                        (jnp.asarray(moved), jnp.asarray(moved_depth), jnp.asarray(kept)))
                    sides.append(np.asarray(_explicit_residual(shifted, z, coef, offset)))
                out.append((sides[0] - sides[1]) / (2.0 * h))
        return np.stack(out, axis=1)

    def records(self) -> tuple:
        """Each warp as params.json writes it, with the standard errors of its parameters."""
        out, first = [], 0
        for warp in self.warps:
            record = warp.to_dict()
            n = len(warp.params)
            if self.stderr is not None:
                err = [None if not np.isfinite(e) else float(e) for e in self.stderr[first:first + n]]
                first += n
                stderr = {"shift_px": err[:2]}
                if warp.kind == "similarity":
                    stderr["rotation_deg"] = None if err[2] is None else float(np.degrees(err[2]))
                    stderr["scale"] = None if err[3] is None else float(np.exp(warp.params[3]) * err[3])
                elif warp.kind == "affine":
                    stderr["matrix_2x2"] = err[2:]
                record["stderr"] = stderr
            out.append(record)
        return tuple(out)


#: Registration rounds (a one-start fit and a warp refinement each) at most.
ALIGN_ROUNDS = 4
#: Solver steps per solve in a registration round's fit: the round only needs a
#: prediction that carries about the right blur, and on a badly registered pair
#: the loss is rough enough that a robust round crept for 189 steps (38 s of a
#: 63 s fit of fran_front moved by (1.2, -0.7) px and 0.5 deg).
ALIGN_ROUND_STEPS = 30
#: An aligned fit compares the images from this many pixels inside the resampled
#: mask's edge. Measured on fran_front seen from a camera moved by (0.6, 0.8) px,
#: fitted with the true warp: all of the mask gave sss_level +58 %, correction
#: -32 %; without a 2 px rim, -5 % and -2 %.
ALIGN_RIM_PX = 2
#: The warp has settled when no corner of the mask's bounding box moves more (px).
ALIGN_SETTLED_PX = 0.01


def _corners(mask) -> np.ndarray:
    """The corners (4, 2) of the mask's bounding box, (row, col)."""
    rows, cols = np.nonzero(mask > 0)
    return np.array([[rows.min(), cols.min()], [rows.min(), cols.max()],
                     [rows.max(), cols.min()], [rows.max(), cols.max()]], np.float64)


def _warp_change(a, b, mask) -> float:
    """How far (px) two warps take any corner of the mask's bounding box apart."""
    corners = _corners(mask)
    return float(np.abs(a.map_points(corners) - b.map_points(corners)).max())


class _Path:
    """The solve so far: objective (with its robust weights and active set), the
    unknowns and the last solve's status."""

    def __init__(self, objective, z):
        self.objective, self.z = objective, z
        self.converged, self.failure, self.interrupted = True, "", False
        self.messages: list[str] = []
        self.delta = 0.0

    def extend(self, record):
        self.z = record.z
        self.converged, self.failure = record.converged, record.failure
        self.interrupted = record.interrupted


def _solve(problem, options, steps, before_first_step=None) -> _Path:
    """Multi-start, robust reweighting and the active set (steps 2-4 above).

    The starts stop at the looser :data:`~.solve.SCREEN_TOL` (they only pick the
    basin); the best is solved again at the full tolerance, by the robust rounds
    or, without them, by a ``refine`` solve. Both solvers carry their
    tolerances as arrays, so they share one compiled step.
    Stops early, keeping the best point so far, when ``steps.stop`` asks.
    ``before_first_step()`` runs after the first poll of ``steps.stop`` (the fit
    waits there for its solver's compilation).
    """
    screen = make_solver(options.solver, tolerance=SCREEN_TOL)
    solver = make_solver(options.solver, tolerance=RTOL)
    path = _Path(problem.objective, problem.z_base)
    if not problem.param.size:
        return path
    # One poll before the first step: the start search can take a while, and
    # there is nothing to report yet.
    if steps.stop_requested():
        raise FitInterrupted("stop: the fit was interrupted before its first solver step")
    if before_first_step is not None:
        before_first_step()

    def run(label, z0, with_solver=solver, arrived=None, max_steps=None, state=None):
        steps.begin(label)
        stall = SCREEN_STALL_TOL if with_solver is screen else STALL_TOL
        return run_solver(with_solver, path.objective, z0, max_steps or options.max_steps, steps,
                          steps.stop_requested, arrived, NOISE_TOL, stall, SOLVER_JACOBIAN, state)

    # Multi-start from the lowest local minima of the blur scan; keep the best.
    # Successive halving: every start first takes HALVING_STEPS steps, and only
    # the better half of them (by loss) goes on to the screening tolerance. A
    # start that comes within SAME_BASIN of a minimum an earlier start reached
    # would only walk the rest of that start's way: it ends there.
    best, minima, records = None, [], []
    interrupted = False

    def known_basin(z):
        # NumPy, not jax.numpy: this runs on the host after every step.
        z = np.asarray(z)
        return any(float(np.max(np.abs(z - m))) < SAME_BASIN for m in minima)

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
    path.extend(best)
    path.interrupted = interrupted  # any start, not necessarily the best

    if options.robust is None or path.interrupted:
        if not path.interrupted:
            path.extend(run("refine", path.z))
        _active_set(problem, path, run)
        return path

    # Robust reweighting rounds, warm-started, then the active set. The starts
    # were ranked under plain least squares with the weights' sign free; the
    # robust loss with the sign imposed can rank two basins the other way (an
    # 8-bit JPEG of fran_front: least squares preferred sss_level 843 by 0.4 %
    # of its loss, the robust loss preferred 600). So the best start of another
    # basin is carried through the same rounds, and the two are compared on one
    # robust objective.
    masks = [np.asarray(p.residual_weight) for p in problem.data]
    others = [(i, r) for i, r in sorted(records, key=lambda item: item[1].final)
              if float(np.max(np.abs(np.asarray(r.z) - np.asarray(best.z)))) >= SAME_BASIN]
    finished = []
    for number, record in [(None, best)] + others[:1]:
        path = _Path(problem.objective, record.z)
        path.extend(record)
        prefix = "" if number is None else f"start {number}, "
        for round_ in range(_ROBUST_ROUNDS):
            residuals = _residuals(problem, path)
            path.delta = robust_scale(residuals, masks, options.robust)
            # device_put: jnp.asarray would compile a small copy for the new shape.
            u = tuple(jax.device_put(np.asarray(x)) for x in robust_weights(residuals, path.delta, options.robust))
            path.objective = eqx.tree_at(lambda o: o.robust, path.objective, u)
            path.extend(run(f"{prefix}robust {round_ + 1}", path.z))
            if path.interrupted:
                break
        _active_set(problem, path, run, prefix)
        finished.append(path)
        if path.interrupted:
            break
    if finished[-1].interrupted:
        # A stop asked for during a later candidate: report the first, as interrupted.
        finished[0].interrupted = True
        return finished[0]
    return _choose_basin(problem, finished, options.robust) if len(finished) > 1 else finished[0]


def _residuals(problem, path) -> list[np.ndarray]:
    """Each pair's target minus the prediction at ``path``'s point, (H, W, C')."""
    preds = _evaluate(path.objective, path.z, np.asarray(False))["predictions"]
    return [np.asarray(p.target) - np.asarray(q) for p, q in zip(problem.data, preds)]


def _choose_basin(problem, finished, robust):
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

    residuals = [_residuals(problem, c) for c in finished]
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
        chosen.messages.append(
            f"sss_level: another basin fits as well within the noise, at sss_level {', '.join(rivals)} against "
            f"{level:.4g}; with the weights free the blur scale trades against them, and its standard error "
            "covers one basin only. Hold the weights at a measured profile (fix weights=...) to decide"
        )
    return chosen


def _active_set(problem, path, run, prefix: str = "") -> None:
    """Weights are ratios on the simplex: hold negative ones at 0, re-solving
    after each change. An interrupted fit still gets this pass, without the
    re-solves (only the linear unknowns are projected again): its estimate must
    be a valid profile too, ready to render."""
    nb = int(path.objective.active.shape[0])
    if not problem.linear_weights or nb < 2:
        return
    for round_ in range(nb):
        coef = np.asarray(_evaluate(path.objective, path.z, np.asarray(False))["coef"])
        active = np.asarray(path.objective.active)
        negative = (coef * np.sign(coef.sum(axis=0)) < 0) & (active > 0)
        if not negative.any():
            break
        active = jnp.asarray(np.where(negative, 0.0, active))
        path.objective = eqx.tree_at(lambda o: o.active, path.objective, active)
        if not path.interrupted:
            path.extend(run(f"{prefix}active set {round_ + 1}", path.z))
    held = np.asarray(path.objective.active) == 0
    held = held[:, 0] if problem.channels == 1 else held
    if held.any():
        names = ", ".join(_entry("weights", i) for i in zip(*np.nonzero(held)))
        path.messages.append(f"{names}: held at 0 (the unconstrained least squares made them negative)")


def _report(problem, path, single, steps, nuisance=None) -> FitResult:
    """The estimate, its uncertainty and diagnostics (step 5 above)."""
    param, roles, data, c_tgt = problem.param, problem.roles, problem.data, problem.channels
    robust, max_steps = problem.options.robust, problem.options.max_steps
    messages = [*problem.notes, *path.messages]
    final = _evaluate(path.objective, jnp.asarray(path.z), np.asarray(True))
    ratios, coef, offset = (np.asarray(final[k]) for k in ("ratios", "coef", "offset"))
    natural = {k: np.asarray(v) for k, v in param.natural(np.asarray(path.z, np.float64)).items()}
    if problem.linear_weights:
        gain0 = coef.sum(axis=0)
        weights = coef / gain0
        weights = weights[:, 0] if c_tgt == 1 else weights
    else:
        gain0 = coef[0]
        weights = natural["weights"]
        if weights.ndim == 2 and weights.shape[1] == 1 and c_tgt == 1:
            weights = weights[:, 0]
    if np.any(gain0 <= 0):
        messages.append("gain: not positive; the target does not look like a blur of the source")
    natural["weights"] = weights

    # Uncertainty and undetermined parameters.
    columns = None if nuisance is None else nuisance.columns(path.objective, path.z, coef, offset)
    unc = gauss_newton_uncertainty(
        path.objective, final["linearisation"], problem.scales.correction,
        None if robust is None else (robust, path.delta), columns,
    )
    if nuisance is not None:
        nuisance.stderr = unc.nuisance_stderr
    if problem.linear_weights:
        active = np.asarray(path.objective.active)
    else:
        active = np.ones((problem.variances.shape[0], c_tgt))
    c_err = unc.stderr.get("correction")
    flags, reasons = structural_reasons(
        roles, problem.model, problem.scales, natural, weights, active,
        None if c_err is None else float(c_err),
    )
    messages.extend(reasons)
    stderr, undetermined, numeric_only = _combine_flags(roles, natural, unc, flags)
    if numeric_only:
        messages.append(
            f"{', '.join(numeric_only)}: not determined by the data (a degenerate direction "
            "or a standard error as large as the value)"
        )

    # Goodness of fit and alignment.
    # At each pair's own size (a canvas is only padding).
    fitted = [crop(q, shape) for q, shape in zip(final["predictions"], problem.shapes)]
    # Scored where the residual counted (the mask, less any fit_weight exclusions).
    masks = [np.asarray(p.residual_weight) for p in problem.given]
    targets = [np.asarray(p.target) for p in problem.given]
    size = np.array([m.sum() for m in masks])
    psnr = _mean_psnr(fitted, targets, masks)
    ssim = float(np.average([masked_ssim(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=size))
    messages.extend(_concentrated_residual(fitted, targets, masks, single))
    for i, (f, t, m) in enumerate(zip(fitted, targets, masks)):
        dy, dx = misalignment(f, t, m)
        if max(abs(dy), abs(dx)) > MISALIGNMENT_PX:
            where = "" if single else f"pair {i}: "
            messages.append(
                f"{where}target appears shifted by ({dy:+.1f}, {dx:+.1f}) px (dy, dx) relative to "
                "the source; align the images, the fitted parameters are unreliable"
            )
    if path.interrupted:
        messages.append(
            f"solver: interrupted after {len(steps.losses)} steps; the estimate is the best point reached"
        )
    elif not path.converged:
        messages.append(f"solver: not converged ({path.failure or f'max_steps={max_steps} reached'})")

    squeeze = (lambda a: a[0]) if single else (lambda a: a)
    return FitResult(
        params=None,
        values={k: np.asarray(natural[k], np.float64) for k in PARAM_NAMES},
        stderr=stderr,
        undetermined=tuple(undetermined),
        fixed={k: np.asarray(param.values[k]).tolist() for k in PARAM_NAMES if roles[k] == "fixed"},
        gauge=problem.options.gauge,
        loss=float(final["loss"]),
        sigma=unc.sigma,
        psnr=psnr,
        ssim=ssim,
        converged=bool(path.converged) and not path.interrupted,
        iterations=len(steps.losses),
        history=np.asarray(steps.losses, np.float64),
        gain=squeeze(ratios * gain0),
        offset=squeeze(offset),
        mix=natural.get("mix"),
        fitted=[f[..., 0] if p.target_ndim == 2 else f for f, p in zip(fitted, data)],
        warnings=tuple(messages),
        model=problem.model,
        tap_weights=None,
        interrupted=bool(path.interrupted),
        stages=tuple(steps.stages),
        start_profile={
            "weights": problem.start_weights,
            "variances": np.asarray(problem.variances, np.float64),
        },
        vignetting=_vignetting_record(natural, unc),
        light_terms=_light_terms_record(natural, unc),
    )


#: A fit warns when a handful of pixels (this share of the mask, at least one)
#: carries more than :data:`CONCENTRATED_SHARE` of the squared residual. Under
#: noise alone the worst 0.1 % of Gaussian residuals carry about 1.3 % of it; on
#: the seven bundled pairs' plain fits it was 0.6-2.2 % (measured 2026-11-26). A wrong buffer pixel that a term amplifies (a
#: normal facing away from the camera) put 90 % of the loss on ten pixels.
CONCENTRATED_PIXELS = 0.001
CONCENTRATED_SHARE = 0.25


def _concentrated_residual(fitted, targets, masks, single) -> list[str]:
    """A warning for each pair whose squared residual sits on a handful of pixels."""
    out = []
    for i, (f, t, m) in enumerate(zip(fitted, targets, masks)):
        weight = np.asarray(m, np.float64)
        per_pixel = np.sum((np.asarray(t, np.float64).reshape(f.shape) - f) ** 2, axis=-1) * weight
        total = float(per_pixel.sum())
        if not total > 0.0:
            continue
        count = max(1, int(np.ceil(CONCENTRATED_PIXELS * np.count_nonzero(weight))))
        flat = per_pixel.ravel()
        worst = np.argpartition(flat, -count)[-count:]
        share = float(flat[worst].sum()) / total
        if share > CONCENTRATED_SHARE:
            row, col = np.unravel_index(int(np.argmax(flat)), per_pixel.shape)
            where = "" if single else f"pair {i}: "
            out.append(
                f"{where}residual: {count} pixel(s) ({100.0 * count / np.count_nonzero(weight):.2g} % of the mask) "
                f"carry {100.0 * share:.0f} % of the squared residual, the worst at row {row}, column {col}; "
                "a buffer may be wrong there (a normal facing away, a silhouette, a clipped or hot pixel): "
                "look at the residual in report.png, or leave those pixels out of the mask"
            )
    return out


def _light_terms_record(natural, unc) -> dict | None:
    """The light-aware terms as params.json writes them (None without any).

    A held term has a null standard error and is listed under ``fixed``.
    """
    used = {term: k for term, k in LIGHT_UNKNOWNS.items() if k in natural}
    if not used:
        return None
    def number(x):
        # The law's albedo is one per channel; the other terms one number each.
        x = np.asarray(x, np.float64)
        return float(x) if x.ndim == 0 else x.tolist()

    record = {term: number(natural[k]) for term, k in used.items()}
    record["stderr"], record["fixed"] = {}, []
    for term, k in used.items():
        if k not in unc.stderr:
            record["stderr"][term] = None
            record["fixed"].append(term)
            continue
        err = np.asarray(unc.stderr[k], np.float64)
        record["stderr"][term] = masked_list(err, ~np.isfinite(err))
    return record


def _vignetting_record(natural, unc) -> dict | None:
    """The fitted fall-off field as params.json writes it (None when not fitted)."""
    if "vignetting" not in natural:
        return None
    a = np.asarray(natural["vignetting"], np.float64)
    err = np.asarray(unc.stderr["vignetting"], np.float64)
    return {
        "model": "gain field 1 + a1 rho^2 + a2 rho^4, rho = distance from the frame's centre / half-diagonal",
        "coefficients": a.tolist(),
        "stderr": [None if not np.isfinite(e) else float(e) for e in err],
        "corner_gain": float(1.0 + a.sum()),
    }


def _combine_flags(roles, natural, unc, flags):
    """Standard errors (None where fixed or undetermined), the undetermined entry
    names, and those flagged by the numerical test alone."""
    stderr, undetermined, numeric_only = {}, [], []
    for name in PARAM_NAMES:
        if roles[name] == "fixed":
            stderr[name] = None
            continue
        shape = np.shape(natural[name])
        struct = np.broadcast_to(flags.get(name, False), shape)
        numeric = np.broadcast_to(unc.undetermined.get(name, False), shape)
        flag = struct | numeric
        stderr[name] = masked_list(unc.stderr[name], flag) if name in unc.stderr else None
        if roles[name] == "unused" or shape == ():
            undetermined.extend([name] if flag.all() else [])
            numeric_only.extend([name] if shape == () and numeric & ~struct else [])
        else:
            undetermined.extend(_entry(name, i) for i in zip(*np.nonzero(flag)))
            numeric_only.extend(_entry(name, i) for i in zip(*np.nonzero(numeric & ~struct)))
    return stderr, undetermined, numeric_only
