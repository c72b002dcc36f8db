"""The fit's report: a solved problem's estimate, uncertainty and diagnostics.

:func:`summarise` turns a :class:`~.search.SolvePath` into a :class:`FitResult`
(step 5 of :mod:`invsss.estimator.fit`): the natural values, standard errors and
undetermined parameters (:mod:`.uncertainty`), PSNR, SSIM and the warnings of
:mod:`.diagnostics`.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..forward.params import PARAM_NAMES, entry_name
from .blur_width import blur_record, under_a_pixel_warning
from .canvas import crop
from .diagnostics import MISALIGNMENT_PX, masked_psnr, masked_ssim, misalignment
from .parametrisation import LIGHT_UNKNOWNS
from .pigment import term_names
from .problem import evaluate
from .result import FitResult, masked_list
from .uncertainty import gauss_newton_uncertainty, structural_reasons

__all__ = ["concentrated_residual", "entry_name", "mean_psnr", "summarise"]


def mean_psnr(fitted, targets, masks) -> float:
    """PSNR of every pair on its mask, averaged with the masks' sizes as weights."""
    size = np.array([m.sum() for m in masks])
    return float(np.average([masked_psnr(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=size))


def summarise(problem, path, single, steps, nuisance=None) -> FitResult:
    """The estimate, its uncertainty and diagnostics (step 5 of :mod:`invsss.estimator.fit`).

    ``nuisance`` (an aligned fit's :class:`~.stages.alignment.WarpSensitivity`)
    adds unknowns estimated outside the solve to the covariance.
    """
    param, roles, data, c_tgt = problem.param, problem.roles, problem.data, problem.channels
    messages = [*problem.notes, *path.messages]
    final = evaluate(path.objective, jnp.asarray(path.z), np.asarray(True))
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
    unc, stderr, undetermined = _uncertainty(problem, path, final, natural, nuisance, messages)
    blur = blur_record(problem.model, natural, problem.scales.depth, problem.scales.slope, unc,
                       problem.options.focal_px)
    unresolved = under_a_pixel_warning(blur)
    if unresolved:
        messages.append(unresolved)
    if path.rival_basins is not None:
        # Where the path's own messages end, as before the uncertainty's reasons.
        messages.insert(len(problem.notes) + len(path.messages),
                        rival_basin_warning(path.rival_basins, "sss_level" not in undetermined))
    fitted, psnr, ssim = _goodness(problem, final, single, messages)
    if path.interrupted:
        messages.append(
            f"solver: interrupted after {len(steps.losses)} steps; the estimate is the best point reached"
        )
    elif not path.converged:
        messages.append(f"solver: not converged ({path.failure or f'max_steps={problem.options.max_steps} reached'})")

    squeeze = (lambda a: a[0]) if single else (lambda a: a)
    return FitResult(
        params=None,  # type: ignore[arg-type]  # filled in by estimator.core (dataclasses.replace)
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
        blur=blur,
        pigment=_pigment_record(problem, path, natural, unc, single),
    )


def rival_basin_warning(rival_basins, level_determined: bool) -> str:
    """The warning for :func:`~.search.choose_basin`'s rivals. Its caveat about the
    standard error is given only where there is one: where the data do not
    determine ``sss_level`` at all, another warning says so."""
    level, rivals = rival_basins
    caveat = ", and its standard error covers one basin only" if level_determined else ""
    return (
        f"sss_level: another basin fits as well within the noise, at sss_level {', '.join(rivals)} against "
        f"{level:.4g}; with the weights free the blur scale trades against them{caveat}. Hold the weights "
        "at a measured profile (fix weights=...) to decide"
    )


def _uncertainty(problem, path, final, natural, nuisance, messages):
    """Standard errors and undetermined parameters: ``(unc, stderr, undetermined)``;
    appends the reasons to ``messages``."""
    coef, offset = np.asarray(final["coef"]), np.asarray(final["offset"])
    robust = problem.options.robust
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
        active = np.ones((problem.variances.shape[0], problem.channels))
    c_err = unc.stderr.get("correction")
    flags, reasons = structural_reasons(
        problem.roles, problem.model, problem.scales, natural, natural["weights"], active,
        None if c_err is None else float(c_err),
    )
    messages.extend(reasons)
    stderr, undetermined, numeric_only = _combine_flags(problem.roles, natural, unc, flags)
    if numeric_only:
        messages.append(
            f"{', '.join(numeric_only)}: not determined by the data (a degenerate direction "
            "or a standard error as large as the value)"
        )
    return unc, stderr, undetermined


def _goodness(problem, final, single, messages):
    """Goodness of fit and alignment: ``(fitted, psnr, ssim)``; appends warnings to ``messages``."""
    # At each pair's own size (a canvas is only padding).
    fitted = [crop(q, shape) for q, shape in zip(final["predictions"], problem.shapes)]
    # Scored where the residual counted (the mask, less any fit_weight exclusions).
    masks = [np.asarray(p.residual_weight) for p in problem.given]
    targets = [np.asarray(p.target) for p in problem.given]
    size = np.array([m.sum() for m in masks])
    psnr = mean_psnr(fitted, targets, masks)
    ssim = float(np.average([masked_ssim(f, t, m) for f, t, m in zip(fitted, targets, masks)], weights=size))
    messages.extend(concentrated_residual(fitted, targets, masks, single))
    for i, (f, t, m) in enumerate(zip(fitted, targets, masks)):
        dy, dx = misalignment(f, t, m)
        if max(abs(dy), abs(dx)) > MISALIGNMENT_PX:
            where = "" if single else f"pair {i}: "
            messages.append(
                f"{where}target appears shifted by ({dy:+.1f}, {dx:+.1f}) px (dy, dx) relative to "
                "the source; align the images, the fitted parameters are unreliable"
            )
    return fitted, psnr, ssim


#: A fit warns when a handful of pixels (this share of the mask, at least one)
#: carries more than :data:`CONCENTRATED_SHARE` of the squared residual. Under
#: noise alone the worst 0.1 % of Gaussian residuals carry about 1.3 % of it; on
#: the seven bundled pairs' plain fits it was 0.6-2.2 % (measured 2026-11-26). A wrong
#: buffer pixel that a term amplifies (a normal facing away from the camera) put 90 % of
#: the loss on ten pixels.
CONCENTRATED_PIXELS = 0.001
CONCENTRATED_SHARE = 0.25
#: ... unless the pair's PSNR (as the fit reports it) is at least this (dB): a fit
#: that good leaves rounding, which has no wrong buffer to point at (a target that
#: was the source itself warned at 82.8 dB).
CONCENTRATED_FLOOR_DB = 60.0


def concentrated_residual(fitted, targets, masks, single) -> list[str]:
    """A warning for each pair whose squared residual sits on a handful of pixels."""
    out = []
    for i, (f, t, m) in enumerate(zip(fitted, targets, masks)):
        weight = np.asarray(m, np.float64)
        per_pixel = np.sum((np.asarray(t, np.float64).reshape(f.shape) - f) ** 2, axis=-1) * weight
        total = float(per_pixel.sum())
        if not total > 0.0:
            continue
        if masked_psnr(f, np.asarray(t, np.float64).reshape(f.shape), weight) >= CONCENTRATED_FLOOR_DB:
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


def _pigment_record(problem, path, natural, unc, single) -> dict | None:
    """The fitted pigment field as params.json writes it (None when not fitted), with
    the PSNR of the same fit with the field set to 1 (what the field bought)."""
    if "pigment" not in natural:
        return None
    a = np.asarray(natural["pigment"], np.float64)
    err = np.asarray(unc.stderr["pigment"], np.float64)
    # The same blur, the field removed and the gains solved again: one more call of
    # the compiled evaluation, at another point.
    z = np.array(path.z)  # its own dtype: the compiled evaluation is reused
    first, stop = path.objective.param.layout()["pigment"]
    z[first:stop] = 0.0
    plain = evaluate(path.objective, jnp.asarray(z), np.asarray(False))
    fitted = [crop(q, shape) for q, shape in zip(plain["predictions"], problem.shapes)]
    masks = [np.asarray(p.residual_weight) for p in problem.given]
    psnr_without = mean_psnr(fitted, [np.asarray(p.target) for p in problem.given], masks)
    squeeze = (lambda x: x[0]) if single else (lambda x: x)
    degree = problem.options.pigment
    return {
        "model": "gain field per target channel: 1 + sum_j a_j phi_j(u, v), u and v from -1 to 1 across the frame",
        "degree": degree,
        "terms": term_names(degree),
        "coefficients": squeeze(a).tolist(),
        "stderr": masked_list(squeeze(err), ~np.isfinite(squeeze(err))),
        "estimate": a.tolist(),
        "psnr_without": float(psnr_without),
    }


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
            undetermined.extend(entry_name(name, i) for i in zip(*np.nonzero(flag)))
            numeric_only.extend(entry_name(name, i) for i in zip(*np.nonzero(numeric & ~struct)))
    return stderr, undetermined, numeric_only
