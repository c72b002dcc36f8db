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

import numbers

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


def _tap_weights(spec, model):
    if spec is None:
        spec = "thesis" if model == "thesis" else "jimenez"
    try:
        taps = tap_weight_set(spec, jnp.float64)
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


def _blur_at_zero(roles, param, scales, fixed, variances):
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
def _evaluate(objective, z):
    """Everything needed after a solve, in one compiled function: the linear
    unknowns, predictions, loss and the linearisation for the covariance."""
    _, _, ratios, coef, offset = objective.linear(z)
    return {
        "ratios": ratios,
        "coef": coef,
        "offset": offset,
        "predictions": objective.predictions(z),
        "loss": objective.loss(z),
        "linearisation": linearise(objective, z, coef, offset),
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
        _, taps = _tap_weights(tap_weights, model)
        return _fit_checked(
            data, single, model, roles, fixed, profile, profile_w, profile_v, gauge, solver,
            n_starts, max_steps, taps, tap_label, progress, robust,
        )


def _fit_checked(data, single, model, roles, fixed, profile, profile_w, profile_v, gauge, solver_name,
                 n_starts, max_steps, taps, tap_label, progress, robust):
    scales = data_scales(data)
    param, z_base = _build(data, roles, fixed, profile_w, profile_v, scales)
    variances = np.asarray(fixed.get("variances", profile_v))
    c_tgt = data[0].channels[1]
    linear_weights = roles["weights"] == "linear"
    nb = variances.shape[0] if linear_weights else 1
    on_mask = np.concatenate([np.asarray(p.target)[np.asarray(p.mask) > 0].ravel() for p in data])
    scale = float(np.std(on_mask)) or 1.0
    objective = Objective(
        param,
        tuple(data),
        taps,
        tuple(jnp.ones_like(p.target) for p in data),
        jnp.ones((nb, c_tgt)),
        jnp.asarray(scale),
        model,
        linear_weights,
    )
    total = float(sum(np.sum(np.asarray(p.mask)) for p in data)) * c_tgt
    counter = _Counter(progress, 2.0 * scale**2 / total)
    solver = make_solver(solver_name)
    messages: list[str] = []

    # Multi-start from the lowest local minima of the blur scan; keep the best.
    history, converged, z = np.zeros(0), True, z_base
    if param.size:
        blur0 = _blur_at_zero(roles, param, scales, fixed, variances)
        starts = choose_starts(
            lambda u: float(_loss(objective, jnp.asarray(u))), param, scales, blur0, z_base, n_starts
        )
        best = None
        for z0 in starts:
            record = run_solver(solver, objective, z0, max_steps, counter)
            if best is None or record.final < best.final:
                best = record
        z, history, converged = best.z, best.history, best.converged

    def refine(obj, z, history):
        if not param.size:
            return z, history, True
        record = run_solver(solver, obj, z, max_steps, counter)
        return record.z, np.concatenate([history, record.history]), record.converged

    # Robust reweighting rounds, warm-started.
    delta = 0.0
    if robust is not None:
        for _ in range(_ROBUST_ROUNDS):
            preds = _evaluate(objective, z)["predictions"]
            residuals = [np.asarray(p.target) - np.asarray(q) for p, q in zip(data, preds)]
            delta = robust_scale(residuals, [np.asarray(p.mask) for p in data], robust)
            u = robust_weights(residuals, delta, robust)
            objective = eqx.tree_at(lambda o: o.robust, objective, tuple(jnp.asarray(x) for x in u))
            z, history, converged = refine(objective, z, history)

    # Active set: weights are ratios on the simplex; hold negative ones at 0.
    if linear_weights and nb > 1:
        for _ in range(nb):
            coef = np.asarray(_evaluate(objective, z)["coef"])
            gain = coef.sum(axis=0)
            negative = (coef * np.sign(gain) < 0) & (np.asarray(objective.active) > 0)
            if not negative.any():
                break
            active = np.where(negative, 0.0, np.asarray(objective.active))
            objective = eqx.tree_at(lambda o: o.active, objective, jnp.asarray(active))
            z, history, converged = refine(objective, z, history)
        held = np.asarray(objective.active) == 0
        if held.any():
            held = held[:, 0] if c_tgt == 1 else held
            names = ", ".join(_entry("weights", i) for i in zip(*np.nonzero(held)))
            messages.append(f"{names}: held at 0 (the unconstrained least squares made them negative)")

    # The estimate.
    final = _evaluate(objective, jnp.asarray(z))
    ratios, coef, offset = (np.asarray(final[k]) for k in ("ratios", "coef", "offset"))
    natural = {k: np.asarray(v) for k, v in param.natural(jnp.asarray(z)).items()}
    if linear_weights:
        gain1 = coef.sum(axis=0)
        weights = coef / gain1
        weights = weights[:, 0] if c_tgt == 1 else weights
    else:
        gain1 = coef[0]
        weights = natural["weights"]
        if weights.ndim == 2 and weights.shape[1] == 1 and c_tgt == 1:
            weights = weights[:, 0]
    gain = ratios * gain1
    if np.any(gain1 <= 0):
        messages.append("gain: not positive; the target does not look like a blur of the source")
    loss = float(final["loss"])
    if len(history):
        history = history * counter.to_loss
    fitted = [np.asarray(q) for q in final["predictions"]]

    # Uncertainty and undetermined parameters.
    unc = gauss_newton_uncertainty(
        objective, final["linearisation"], scales.correction, None if robust is None else (robust, delta)
    )
    natural_all = dict(natural, weights=weights)
    active = np.asarray(objective.active) if linear_weights else np.ones((variances.shape[0], c_tgt))
    c_err = unc.stderr.get("correction")
    flags, reasons = structural_reasons(
        roles, model, scales, natural_all, weights, active, None if c_err is None else float(c_err)
    )
    messages.extend(reasons)
    undetermined, stderr, numeric_only = [], {}, []
    for name in _PARAMS:
        if roles[name] == "fixed":
            stderr[name] = None
            continue
        shape = np.shape(natural_all[name])
        struct = np.broadcast_to(flags.get(name, False), shape)
        numeric = np.broadcast_to(unc.undetermined.get(name, False), shape)
        flag = struct | numeric
        stderr[name] = masked_list(unc.stderr[name], flag) if name in unc.stderr else None
        if roles[name] == "unused" or shape == ():
            undetermined.extend([name] if flag.all() else [])
        else:
            undetermined.extend(_entry(name, i) for i in zip(*np.nonzero(flag)))
        if shape == ():
            numeric_only.extend([name] if numeric & ~struct else [])
        else:
            numeric_only.extend(_entry(name, i) for i in zip(*np.nonzero(numeric & ~struct)))
    if numeric_only:
        messages.append(
            f"{', '.join(numeric_only)}: not determined by the data (a degenerate direction "
            "or a standard error as large as the value)"
        )

    # Goodness of fit and alignment.
    masks = [np.asarray(p.mask) for p in data]
    targets = [np.asarray(p.target) for p in data]
    weights_px = np.array([m.sum() for m in masks])
    psnr = float(np.average([masked_psnr(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=weights_px))
    ssim = float(np.average([masked_ssim(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=weights_px))
    for i, (f, t, m) in enumerate(zip(fitted, targets, masks)):
        dy, dx = misalignment(f, t, m)
        if max(abs(dy), abs(dx)) > MISALIGNMENT_PX:
            where = "" if single else f"pair {i}: "
            messages.append(
                f"{where}target appears shifted by ({dy:+.1f}, {dx:+.1f}) px (dy, dx) relative to "
                "the source; align the images, the fitted parameters are unreliable"
            )
    if not converged:
        messages.append(f"solver: not converged within max_steps={max_steps}")

    params = SSSParams(
        natural["sss_level"], natural["correction"], natural["maxdd"], weights, natural["variances"]
    )
    fixed_out = {k: np.asarray(param.values[k]).tolist() for k in _PARAMS if roles[k] == "fixed"}
    squeeze = (lambda a: a[0]) if single else (lambda a: a)
    return FitResult(
        params=params,
        stderr=stderr,
        undetermined=tuple(undetermined),
        fixed=fixed_out,
        gauge=gauge,
        loss=loss,
        sigma=unc.sigma,
        psnr=psnr,
        ssim=ssim,
        converged=bool(converged),
        iterations=int(len(history)),
        history=np.asarray(history),
        gain=squeeze(gain),
        offset=squeeze(offset),
        mix=natural.get("mix"),
        fitted=[f[..., 0] if p.target_ndim == 2 else f for f, p in zip(fitted, data)],
        warnings=tuple(messages),
        model=model,
        tap_weights=tap_label,
        solver=solver_name,
        profile=profile if isinstance(profile, str) else "",
    )
