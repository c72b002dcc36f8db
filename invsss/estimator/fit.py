"""``fit_pair`` / ``fit_pairs``: estimate the model's parameters from image pairs.

The fit, step by step (each step its own module):

1. check the inputs (:mod:`.inputs`) and the options; decide each parameter's role
   and the unknowns (:mod:`.parametrisation`);
2. scan the loss along the blur scale and start from its ``n_starts`` lowest
   local minima, each with the best correction and maxdd of a small grid
   (:mod:`.initial`);
3. from each start, run the solver (:mod:`.solve`) on the residual with the linear
   unknowns projected out (:mod:`.objective`, :mod:`.projection`); keep the best;
4. refine from the best: robust reweighting rounds (:mod:`.robust`), and an
   active-set pass that holds at 0 any ``sog`` weight the unconstrained least
   squares makes negative (the weights are ratios on the simplex: a negative one
   is not a profile), re-solving after each change;
5. standard errors and undetermined parameters (:mod:`.uncertainty`), PSNR, SSIM
   and a misalignment check (:mod:`.diagnostics`), all in a :class:`FitResult`.

Everything runs in float64 (``jax.enable_x64`` inside the call): the projection's
normal equations over strongly correlated layers need it.
"""

from __future__ import annotations

import dataclasses
import numbers
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..params import SSSParams
from ..passes import tap_weights as tap_weight_set
from ..screen_space import MODELS
from ..validation import InvalidInputError
from .diagnostics import MISALIGNMENT_PX, masked_psnr, masked_ssim, misalignment
from .initial import blur_reference, choose_starts, data_scales
from .inputs import prepare_pairs
from .objective import Objective
from .parametrisation import (
    GAUGES,
    Parametrisation,
    assign_roles,
    check_fix,
    resolve_profile,
)
from .result import FitResult, masked_list
from .robust import check_robust, robust_scale, robust_weights
from .solve import SOLVERS, make_solver, run_solver
from .uncertainty import gauss_newton_uncertainty, linearise, structural_reasons

__all__ = ["fit_pair", "fit_pairs"]

_ROBUST_ROUNDS = 2
_PARAMS = ("sss_level", "correction", "maxdd", "weights", "variances")


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
) -> FitResult:
    """Estimate the screen-space SSS parameters that turn ``source`` into ``target``.

    Minimises a robust masked residual between ``target`` and ``gain * out + offset``
    (``out`` the model applied to ``source``; MODEL.md section 7) with the gains,
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
        refinements) from 1, ``loss`` is in the units of :attr:`FitResult.loss`.
    robust : {"pseudo-huber", "cauchy"} or None
        Robust loss by iterative reweighting (see :mod:`invsss.estimator.robust`).

    Returns
    -------
    FitResult

    Raises
    ------
    InvalidInputError
        Bad shapes, NaN values, non-positive depth, empty mask, unknown model, solver,
        gauge or robust loss, a ``fix`` entry with an unknown name or a bad value,
        ``gauge="sss_level"`` without ``fix["sss_level"]``.

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
    return _fit(
        [(source, target, depth, mask)], True, model, profile, fix, gauge, solver, n_starts,
        max_steps, tap_weights, progress, robust,
    )


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
) -> FitResult:
    """Fit one set of parameters to several pairs (see :func:`fit_pair`).

    ``pairs`` is a sequence of ``(source, target, depth, mask)`` tuples or
    :class:`invsss.ImagePair` objects, all with the same channel layout (sizes may
    differ). The SSS parameters, weights and the RGB -> grey mix are shared; each
    pair has its own offset and gain (the exposure may differ), per target channel.
    ``FitResult.gain`` and ``offset`` then have shape (P, C').
    """
    return _fit(
        pairs, False, model, profile, fix, gauge, solver, n_starts, max_steps, tap_weights,
        progress, robust,
    )


# ----------------------------------------------------------------- options


def _check_options(model, gauge, solver, n_starts, max_steps, progress, robust):
    if model not in MODELS:
        raise InvalidInputError(f"model: expected one of {', '.join(MODELS)}, got {model!r}")
    if gauge not in GAUGES:
        raise InvalidInputError(f"gauge: expected one of {', '.join(GAUGES)}, got {gauge!r}")
    if solver not in SOLVERS:
        raise InvalidInputError(f"solver: expected one of {', '.join(SOLVERS)}, got {solver!r}")
    for name, value in (("n_starts", n_starts), ("max_steps", max_steps)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
            raise InvalidInputError(f"{name}: expected an integer >= 1, got {value!r}")
    if progress is not None and not callable(progress):
        raise InvalidInputError(f"progress: expected a callable or None, got {type(progress).__name__}")
    return check_robust(robust)


def _tap_weights(spec, model, dtype=None):
    if spec is None:
        spec = "thesis" if model == "thesis" else "jimenez"
    try:
        taps = tap_weight_set(spec, dtype)
    except (ValueError, TypeError) as err:
        raise InvalidInputError(str(err)) from None
    return spec if isinstance(spec, str) else np.asarray(taps).tolist(), taps


# ----------------------------------------------------------------- setup


def _initial_weights(profile_weights, k, channels):
    """Starting (or carried) weights of shape (K,) or (K, C') from the profile."""
    w = np.asarray(profile_weights, np.float64)
    if w.shape[0] != k:
        w = np.ones(k)
    if w.ndim == 2 and (channels == 1 or w.shape[1] != channels):
        w = w.mean(axis=1)
    if w.ndim == 1 and channels > 1:
        w = np.repeat(w[:, None], channels, axis=1)
    w = np.maximum(w, 1e-6)
    return w / w.sum(axis=0)


def _build(pairs, roles, fixed, profile_w, profile_v, scales):
    """The parametrisation and the natural starting values of the free blocks."""
    c_src, c_tgt = pairs[0].channels
    variances = fixed.get("variances", profile_v)
    k = variances.shape[0]
    w0 = _initial_weights(profile_w, k, c_tgt)
    if "weights" in fixed:
        w = fixed["weights"]
        if w.ndim == 2 and w.shape[1] not in (1, c_tgt):
            raise InvalidInputError(
                f"fix['weights']: expected one column per target channel ({c_tgt}), got shape {w.shape}"
            )
        if w.shape[0] != k:
            raise InvalidInputError(
                f"fix['weights']: expected {k} rows, one per Gaussian of the profile, got shape {w.shape}"
            )
    carried = {"sss_level": 1.0, "correction": 0.0, "maxdd": scales.slope, "weights": w0, "variances": variances}
    values, reference, start, blocks = {}, {}, {}, []
    for name in _PARAMS:
        role = roles[name]
        if role == "fixed":
            values[name] = jnp.asarray(fixed.get(name, variances if name == "variances" else None))
        elif role in ("unused", "linear"):
            values[name] = jnp.asarray(carried[name])
    if roles["sss_level"] == "free":
        reference["sss_level"] = blur_reference(scales, variances)
        blocks.append(("sss_level", ()))
    if roles["correction"] == "free":
        reference["correction"] = scales.correction
        start["correction"] = 0.1 * scales.correction
        blocks.append(("correction", ()))
    if roles["maxdd"] == "free":
        reference["maxdd"] = scales.slope
        blocks.append(("maxdd", ()))
    if roles["variances"] == "free":
        reference["variances"] = np.asarray(variances)
        blocks.append(("variances", (k,)))
    if roles["weights"] == "free":
        if k == 1:
            values["weights"] = jnp.ones((1,) if c_tgt == 1 else (1, c_tgt))
        else:
            blocks.append(("weights", (k - 1,) if c_tgt == 1 else (k - 1, c_tgt)))
            start["weights"] = w0
            reference["weights"] = 1.0
    if c_src == 3 and c_tgt == 1:
        blocks.append(("mix", (2,)))
        start["mix"] = np.full(3, 1.0 / 3.0)
        reference["mix"] = 1.0
    if len(pairs) > 1:
        blocks.append(("gain_ratio", (len(pairs) - 1, c_tgt)))
        start["gain_ratio"] = np.ones((len(pairs) - 1, c_tgt))
        reference["gain_ratio"] = 1.0
    param = Parametrisation(
        tuple(blocks), {k_: jnp.asarray(v) for k_, v in reference.items()}, values
    )
    natural0 = {name: start.get(name, reference[name]) for name, _ in blocks}
    return param, param.unknowns(natural0)


def _blur_at_zero(roles, scales, fixed, variances):
    if roles["sss_level"] == "free":
        return 2.0  # by construction of the reference (initial.blur_reference)
    if roles["variances"] == "free":
        return float(fixed["sss_level"]) * float(np.sqrt(np.max(variances))) / scales.depth
    return None


def _entry(name, index) -> str:
    """``"weights[2]"`` or ``"weights[2,0]"`` for an entry of an array parameter."""
    return f"{name}[{','.join(str(int(i)) for i in index)}]"


# ----------------------------------------------------------------- jitted pieces


@eqx.filter_jit
def _loss(objective, z):
    return objective.loss(z)


@eqx.filter_jit
def _evaluate(objective, z, with_jacobian):
    """Everything needed after a solve, in one compiled function: the linear
    unknowns, predictions, loss and, if the traced flag ``with_jacobian`` is set,
    the linearisation for the covariance (a ``lax.cond``: one compilation serves
    the cheap calls of the refinement loops and the final one)."""
    _, _, ratios, coef, offset = objective.linear(z)

    def full():
        return linearise(objective, z, coef, offset)

    def skipped():
        return jax.tree_util.tree_map(jnp.zeros_like, jax.eval_shape(full))

    return {
        "ratios": ratios,
        "coef": coef,
        "offset": offset,
        "predictions": objective.predictions(z),
        "loss": objective.loss(z),
        "linearisation": jax.lax.cond(with_jacobian, full, skipped),
    }


# ----------------------------------------------------------------- the fit


class _Counter:
    """Global step count and the progress callback, in loss units."""

    def __init__(self, progress, to_loss):
        self.progress, self.to_loss, self.count = progress, to_loss, 0

    def __call__(self, half_sum_squares):
        self.count += 1
        if self.progress is not None:
            self.progress(self.count, half_sum_squares * self.to_loss)


def _fit(pairs, single, model, profile, fix, gauge, solver, n_starts, max_steps, tap_weights, progress, robust):
    robust = _check_options(model, gauge, solver, n_starts, max_steps, progress, robust)
    tap_label, _ = _tap_weights(tap_weights, model)
    fixed = check_fix(fix)
    roles = assign_roles(model, gauge, fixed)
    with jax.enable_x64(True):
        profile_w, profile_v = resolve_profile(profile)
        data = prepare_pairs(pairs)
        _, taps = _tap_weights(tap_weights, model, jnp.float64)
        problem = _Problem(data, model, roles, fixed, profile_w, profile_v, taps)
        result = _solve(problem, make_solver(solver), n_starts, max_steps, progress, robust)
        result = _report(problem, result, single, gauge, robust, max_steps)
    # Rebuild the parameters outside float64 mode: the caller gets arrays of their
    # own default precision, ready for render().
    params = SSSParams(*(result.values[k] for k in _PARAMS))
    label = os.fspath(profile) if isinstance(profile, (str, os.PathLike)) else ""
    return dataclasses.replace(result, params=params, solver=solver, profile=label, tap_weights=tap_label)


class _Problem:
    """The checked inputs, the parametrisation and the (initial) objective."""

    def __init__(self, data, model, roles, fixed, profile_w, profile_v, taps):
        self.data, self.model, self.roles, self.fixed = data, model, roles, fixed
        self.scales = data_scales(data)
        self.param, self.z_base = _build(data, roles, fixed, profile_w, profile_v, self.scales)
        self.variances = np.asarray(fixed.get("variances", profile_v))
        self.channels = data[0].channels[1]
        self.linear_weights = roles["weights"] == "linear"
        nb = self.variances.shape[0] if self.linear_weights else 1
        on_mask = np.concatenate([np.asarray(p.target)[np.asarray(p.mask) > 0].ravel() for p in data])
        scale = float(np.std(on_mask)) or 1.0
        self.objective = Objective(
            self.param,
            tuple(data),
            taps,
            tuple(jnp.ones_like(p.target) for p in data),
            jnp.ones((nb, self.channels)),
            jnp.asarray(scale),
            model,
            self.linear_weights,
        )
        total = float(sum(np.sum(np.asarray(p.mask)) for p in data)) * self.channels
        # 0.5 * sum(rho^2) -> the reported loss (see objective.py).
        self.to_loss = 2.0 * scale**2 / total


class _Path:
    """The solve so far: objective (with its robust weights and active set), the
    unknowns, the loss history along the way and the last solve's status."""

    def __init__(self, objective, z):
        self.objective, self.z = objective, z
        self.history, self.converged, self.failure = np.zeros(0), True, ""
        self.messages: list[str] = []
        self.delta = 0.0

    def extend(self, record):
        self.z = record.z
        self.history = np.concatenate([self.history, record.history])
        self.converged, self.failure = record.converged, record.failure


def _solve(problem, solver, n_starts, max_steps, progress, robust) -> _Path:
    """Multi-start, robust reweighting and the active set (steps 2-4 above)."""
    param = problem.param
    counter = _Counter(progress, problem.to_loss)
    path = _Path(problem.objective, problem.z_base)
    if not param.size:
        return path

    # Multi-start from the lowest local minima of the blur scan; keep the best.
    blur0 = _blur_at_zero(problem.roles, problem.scales, problem.fixed, problem.variances)
    starts = choose_starts(
        lambda u: float(_loss(path.objective, jnp.asarray(u))),
        param, problem.scales, blur0, problem.z_base, n_starts,
    )
    best = None
    for z0 in starts:
        record = run_solver(solver, path.objective, z0, max_steps, counter)
        if best is None or record.final < best.final:
            best = record
    path.extend(best)

    # Robust reweighting rounds, warm-started.
    if robust is not None:
        masks = [np.asarray(p.mask) for p in problem.data]
        for _ in range(_ROBUST_ROUNDS):
            preds = _evaluate(path.objective, path.z, jnp.asarray(False))["predictions"]
            residuals = [np.asarray(p.target) - np.asarray(q) for p, q in zip(problem.data, preds)]
            path.delta = robust_scale(residuals, masks, robust)
            u = tuple(jnp.asarray(x) for x in robust_weights(residuals, path.delta, robust))
            path.objective = eqx.tree_at(lambda o: o.robust, path.objective, u)
            path.extend(run_solver(solver, path.objective, path.z, max_steps, counter))

    # Active set: weights are ratios on the simplex; hold negative ones at 0.
    nb = int(path.objective.active.shape[0])
    if problem.linear_weights and nb > 1:
        for _ in range(nb):
            coef = np.asarray(_evaluate(path.objective, path.z, jnp.asarray(False))["coef"])
            active = np.asarray(path.objective.active)
            negative = (coef * np.sign(coef.sum(axis=0)) < 0) & (active > 0)
            if not negative.any():
                break
            active = jnp.asarray(np.where(negative, 0.0, active))
            path.objective = eqx.tree_at(lambda o: o.active, path.objective, active)
            path.extend(run_solver(solver, path.objective, path.z, max_steps, counter))
        held = np.asarray(path.objective.active) == 0
        held = held[:, 0] if problem.channels == 1 else held
        if held.any():
            names = ", ".join(_entry("weights", i) for i in zip(*np.nonzero(held)))
            path.messages.append(f"{names}: held at 0 (the unconstrained least squares made them negative)")
    return path


def _report(problem, path, single, gauge, robust, max_steps) -> FitResult:
    """The estimate, its uncertainty and diagnostics (step 5 above)."""
    param, roles, data, c_tgt = problem.param, problem.roles, problem.data, problem.channels
    messages = list(path.messages)
    final = _evaluate(path.objective, jnp.asarray(path.z), jnp.asarray(True))
    ratios, coef, offset = (np.asarray(final[k]) for k in ("ratios", "coef", "offset"))
    natural = {k: np.asarray(v) for k, v in param.natural(jnp.asarray(path.z)).items()}
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
    unc = gauss_newton_uncertainty(
        path.objective, final["linearisation"], problem.scales.correction,
        None if robust is None else (robust, path.delta),
    )
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
    fitted = [np.asarray(q) for q in final["predictions"]]
    masks = [np.asarray(p.mask) for p in data]
    targets = [np.asarray(p.target) for p in data]
    size = np.array([m.sum() for m in masks])
    psnr = float(np.average([masked_psnr(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=size))
    ssim = float(np.average([masked_ssim(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=size))
    for i, (f, t, m) in enumerate(zip(fitted, targets, masks)):
        dy, dx = misalignment(f, t, m)
        if max(abs(dy), abs(dx)) > MISALIGNMENT_PX:
            where = "" if single else f"pair {i}: "
            messages.append(
                f"{where}target appears shifted by ({dy:+.1f}, {dx:+.1f}) px (dy, dx) relative to "
                "the source; align the images, the fitted parameters are unreliable"
            )
    if not path.converged:
        messages.append(f"solver: not converged ({path.failure or f'max_steps={max_steps} reached'})")

    squeeze = (lambda a: a[0]) if single else (lambda a: a)
    return FitResult(
        params=None,
        values={k: np.asarray(natural[k], np.float64) for k in _PARAMS},
        stderr=stderr,
        undetermined=tuple(undetermined),
        fixed={k: np.asarray(param.values[k]).tolist() for k in _PARAMS if roles[k] == "fixed"},
        gauge=gauge,
        loss=float(final["loss"]),
        sigma=unc.sigma,
        psnr=psnr,
        ssim=ssim,
        converged=bool(path.converged),
        iterations=int(len(path.history)),
        history=path.history * problem.to_loss,
        gain=squeeze(ratios * gain0),
        offset=squeeze(offset),
        mix=natural.get("mix"),
        fitted=[f[..., 0] if p.target_ndim == 2 else f for f, p in zip(fitted, data)],
        warnings=tuple(messages),
        model=problem.model,
        tap_weights=None,
    )


def _combine_flags(roles, natural, unc, flags):
    """Standard errors (None where fixed or undetermined), the undetermined entry
    names, and those flagged by the numerical test alone."""
    stderr, undetermined, numeric_only = {}, [], []
    for name in _PARAMS:
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
