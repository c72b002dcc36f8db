"""Standard errors, and which parameters the data cannot determine.

Covariance (Gauss-Newton, the linearised model at the optimum): with ``J`` the
Jacobian of the weighted residual with respect to *all* unknowns -- the free
nonlinear ones and the linear coefficients and offsets the projection eliminated
(inactive coefficients included, so that a weight held at 0 still shows how well
the data separate its Gaussian from the others) --

    cov = sigma^2 (J^T J)^+,    sigma^2 = sum(rho^2) / (N - p),

``N`` the number of weighted residuals, ``p`` the number of unknowns. After a
robust fit the robust weights are taken out of ``J`` and ``sigma^2`` becomes
Huber's ``sum(psi(r)^2) / (N - p) / mean(psi'(r))^2`` (Huber 1981, section 7.6):
without it, down-weighting the noise's tails would shrink ``sigma`` and the
errors would be underestimated. The noise is allowed to be correlated within
blocks of :data:`BLOCK_PX` pixels: each variance is the larger of the one above
and a cluster-robust sandwich ``(J^T J)^+ (sum_b g_b g_b^T) (J^T J)^+ N / (N - p)``,
``g_b`` the sum of ``J_i psi_i`` over block ``b`` (over ``mean(psi')^2`` after a
robust fit; ``psi = r`` for plain least squares). Reported
quantities (natural parameters, and weights ``w_i = beta_i / sum beta``) get their
covariance by the delta method, ``G cov G^T`` with ``G`` their Jacobian.

A parameter is reported *undetermined* (value null) when

1. it lies along a null direction of ``J^T J`` scaled to unit diagonal (eigenvalue
   below :data:`NULL_TOL` of the largest; a column of zeros -- no effect at all --
   is such a direction), i.e. some change of it leaves the image unchanged; or
2. its standard error is as large as the value itself could be: more than the
   value for ``sss_level``, ``maxdd`` and the variances (a factor-of-e
   uncertainty), more than ``max(c, c_ref)`` for the correction (``c_ref`` halves
   the stretch at a typical slope), more than :data:`WEIGHT_VAGUE` for a weight (a
   fraction of the profile); or
3. one of the structural reasons of docs/model.md, section 6 applies (see
   :func:`structural_reasons`): flat depth, ``maxdd`` above every masked slope
   or below all of them, a variance whose weight is ~0 (below
   :data:`ZERO_WEIGHT`), a parameter the model does not use, or two Gaussians
   whose layers differ by a blur narrower than :data:`COINCIDENT_PX` pixel even
   at the largest stretch on the mask (their weights; the thesis's 940 nm
   profile has such a pair, 0.549 and 0.5574 mm^2), or, with the variances
   estimated, a Gaussian narrower than :data:`UNRESOLVED_PX` at the largest
   stretch or wider than the mask at the smallest (its variance).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .parametrisation import LOG_BLOCKS, LOG_LIMIT, SCALED_BLOCKS
from .robust import psi_and_slope

__all__ = [
    "NULL_TOL",
    "WEIGHT_VAGUE",
    "ZERO_WEIGHT",
    "COINCIDENT_PX",
    "UNRESOLVED_PX",
    "FEW_SLOPES",
    "Uncertainty",
    "derived_stderr",
    "linearise",
    "gauss_newton_uncertainty",
    "block_index",
    "BLOCK_PX",
    "structural_reasons",
]

NULL_TOL = 1e-10
WEIGHT_VAGUE = 0.1
ZERO_WEIGHT = 1e-3
COINCIDENT_PX = 0.25
#: An estimated variance whose Gaussian blurs by less than this (px) even at the
#: largest stretch on the mask cannot be told from no blur at all.
UNRESOLVED_PX = 0.1
FEW_SLOPES = 0.01


#: Side (px) of the blocks within which the covariance allows the noise to be
#: correlated (see :func:`gauss_newton_uncertainty`): JPEG's block size.
BLOCK_PX = 8


def block_index(shapes, size: int) -> np.ndarray:
    """For each entry of the images of ``shapes`` ((H, W, C) each), flattened and
    concatenated, the number of its ``size`` x ``size`` pixel block (blocks of
    different images are different)."""
    out, first = [], 0
    for h, w, c in shapes:
        rows, cols = np.mgrid[0:h, 0:w]
        across = -(-w // size)
        index = (rows // size) * across + cols // size
        out.append(np.repeat(index.ravel(), c) + first)
        first += -(-h // size) * across
    return np.concatenate(out) if out else np.zeros(0, int)


class Uncertainty(NamedTuple):
    """Standard errors (NaN where undetermined) and the undetermined entries.

    ``stderr`` and ``undetermined`` map each reported parameter name to arrays of
    its shape; ``sigma`` is the residual standard deviation in the target's units.
    ``linear`` holds what :func:`derived_stderr` needs for a quantity computed from
    the reported ones: their Jacobians with respect to all unknowns, the two
    covariances of those unknowns and the null directions.
    """

    stderr: dict
    undetermined: dict
    sigma: float
    dof: int
    nuisance_stderr: np.ndarray | None = None
    linear: dict | None = None


def derived_stderr(unc: Uncertainty, gradients: dict) -> tuple[float, bool]:
    """Standard error of a quantity ``q(values)`` of the reported values, and whether it is undetermined.

    ``gradients`` maps reported names to ``dq/d value`` (the value's shape); the
    quantity's covariance is the delta method's on the same unknowns as the
    parameters', the larger of the white-noise and the block estimate, and it is
    undetermined where it changes along a null direction. A name not reported
    (a fixed parameter) contributes nothing.
    """
    lin = unc.linear
    if lin is None:
        return float("nan"), True
    g = np.zeros(lin["cov"].shape[0])
    for name, grad in gradients.items():
        if name in lin["jacobians"]:
            g = g + np.asarray(grad, np.float64).ravel() @ lin["jacobians"][name]
    var = max(float(g @ lin["cov"] @ g), float(g @ lin["cov_blocks"] @ g))
    null = lin["null_dirs"]
    size = float(np.linalg.norm(g / lin["scale"]))
    on_null = bool(null.size) and bool(np.any(np.abs(g @ null) > 1e-6 * max(size, 1e-300)))
    return float(np.sqrt(max(var, 0.0))), on_null or not np.isfinite(var)


def _reported(objective, linear_weights: bool, sizes, theta) -> dict:
    n_z, n_coef = sizes
    z = theta[:n_z]
    coef = theta[n_z : n_z + n_coef].reshape(objective.num_basis, -1)
    natural = objective.param.natural(z)
    out = {
        k: natural[k]
        for k in ("sss_level", "correction", "maxdd", "variances", *SCALED_BLOCKS, "law", "transmission",
                  "thickness_scale")
        if k in objective.param.free
    }
    if linear_weights:
        w = coef / jnp.sum(coef, axis=0)
        out["weights"] = w[:, 0] if w.shape[1] == 1 else w
    elif "weights" in objective.param.free:
        w = natural["weights"]
        out["weights"] = w[:, 0] if w.ndim == 2 and w.shape[1] == 1 else w
    return out


def linearise(objective, z, coef, offset) -> dict:
    """What the covariance needs at the optimum (pure; the caller jits it).

    Returns the residual, its Jacobian with respect to ``theta = (z, coef, offset)``,
    the reported quantities and their Jacobians with respect to ``theta``.
    """
    n_z, n_coef = z.size, coef.size
    theta = jnp.concatenate([z, coef.ravel(), offset.ravel()])
    linear_weights = objective.linear_weights and objective.num_basis > 1

    def reported(t):
        return _reported(objective, linear_weights, (n_z, n_coef), t)

    # The residual is linear in (coef, offset) once the basis images are made, so
    # only the z columns go through the blur in forward mode; the others
    # differentiate the mixing of fixed images. One jacfwd over all of theta
    # would push every coef and offset direction through the passes too (11
    # blurred tangents instead of 5 on a 5-Gaussian fit), and compile them.
    def residual_z(u):
        return objective.explicit_residual(u, coef, offset)

    natural = objective.param.natural(z)
    bases, ratios = objective.bases(natural), objective.ratios(natural)

    def residual_linear(t):
        return objective.mixed_residual(bases, ratios, t[:n_coef].reshape(coef.shape), t[n_coef:].reshape(offset.shape))

    jacobian = jnp.concatenate(
        [jax.jacfwd(residual_z)(z), jax.jacfwd(residual_linear)(theta[n_z:])], axis=1
    )
    return {
        "z": z,
        "residual": residual_linear(theta[n_z:]),
        "jacobian": jacobian,
        "values": reported(theta),
        "value_jacobians": jax.jacfwd(reported)(theta),
    }


# Over 80 lines, kept whole: the steps of one covariance on shared intermediates -
# the robust scale, the scaled normal matrix and its null directions, the
# cluster-robust sandwich, the nuisance columns, the reported values' errors.
def gauss_newton_uncertainty(
    objective, lin: dict, correction_ref: float, robust=None, nuisance=None, blocks: bool = True
) -> Uncertainty:
    """Standard errors and undetermined entries from :func:`linearise`'s output.

    ``robust`` is None for plain least squares, else ``(kind, delta)`` of the
    robust loss (``delta`` in target units); see the module docs.

    ``nuisance`` (N, q), optional: the weighted residual's derivatives with
    respect to q more unknowns that were estimated outside this objective (an
    aligned fit's warp). They join ``J`` as columns, so every standard error is
    the marginal one, with those unknowns estimated too rather than taken as
    known; theirs are ``nuisance_stderr`` (NaN where undetermined).

    ``blocks`` False takes the noise as white (no cluster-robust sandwich).
    """
    jac = np.asarray(lin["jacobian"])
    rho = np.asarray(lin["residual"])
    values, jacs = lin["values"], dict(lin["value_jacobians"])
    q = 0
    if nuisance is not None:
        nuisance = np.asarray(nuisance, np.float64).reshape(jac.shape[0], -1)
        q = nuisance.shape[1]
        jac = np.concatenate([jac, nuisance], axis=1)
        # The reported values do not depend on the nuisance unknowns themselves.
        jacs = {k: np.concatenate([np.asarray(g).reshape(-1, jac.shape[1] - q),
                                   np.zeros((int(np.size(values[k])), q))], axis=1)
                for k, g in jacs.items()}
    # objective.weights() in NumPy: this runs on the host, once per fit.
    weights = [np.asarray(p.residual_weight)[..., None] * np.asarray(u)
               for p, u in zip(objective.pairs, objective.robust)]
    shapes = [np.shape(w) for w in weights]
    weighted = np.concatenate([np.asarray(w).ravel() > 0 for w in weights])
    n, p = int(weighted.sum()), jac.shape[1]
    dof = max(n - p, 1)
    if robust is None:
        sigma2 = float(np.sum(rho**2)) / dof
        scores, slope = rho[weighted], 1.0
    else:
        # Undo the robust weights u (rho = sqrt(u) r): Huber's covariance of an
        # M-estimate uses the unweighted Jacobian and the scale
        # sum(psi^2) / (N - p) / mean(psi')^2.
        u = np.concatenate([np.asarray(x).ravel() for x in objective.robust])
        root = np.sqrt(u)
        jac = jac / root[:, None]
        r = (rho / root)[weighted]
        psi, dpsi = psi_and_slope(r, robust[1] / float(objective.scale), robust[0])
        slope = float(np.mean(dpsi))
        sigma2 = float(np.sum(psi**2)) / dof / slope**2
        scores = psi

    # Scale to unit diagonal; a column with no effect keeps scale 1 and becomes a
    # zero eigenvalue, i.e. a null direction along its own axis.
    a = jac.T @ jac
    d = np.sqrt(np.diag(a))
    dead = d <= 1e-9 * max(d.max(), 1e-300)
    d = np.where(dead, 1.0, d)
    c = a / np.outer(d, d)
    lam, u = np.linalg.eigh(c)
    null = lam <= NULL_TOL * max(lam.max(), 1e-300)
    inv = (u[:, ~null] / lam[~null]) @ u[:, ~null].T
    cov_theta = sigma2 * inv / np.outer(d, d)
    # The same covariance with the noise correlated within blocks of BLOCK_PX
    # pixels (a cluster-robust sandwich); each variance below is the larger of
    # the two. Where the noise is white the two agree within the sandwich's own
    # scatter; JPEG's 8 x 8 blocks, demosaicking and sharpening correlate it, and
    # the white-noise errors are then too small.
    cov_blocks = np.zeros_like(cov_theta)
    if blocks:
        index = block_index(shapes, BLOCK_PX)[weighted]
        per_block = np.zeros((int(index.max()) + 1 if index.size else 0, p))
        np.add.at(per_block, index, jac[weighted] * scores[:, None])
        bread = inv / np.outer(d, d)
        cov_blocks = bread @ (per_block.T @ per_block) @ bread * (n / dof) / slope**2
    null_dirs = u[:, null] / d[:, None]  # in theta units

    stderr, undetermined = {}, {}
    z, layout = np.asarray(lin["z"]), objective.param.layout()
    for name, value in values.items():
        g = np.asarray(jacs[name]).reshape(-1, p)
        val = np.asarray(value).ravel()
        var = np.maximum(np.einsum("kp,pq,kq->k", g, cov_theta, g), np.einsum("kp,pq,kq->k", g, cov_blocks, g))
        std = np.sqrt(np.maximum(var, 0.0))
        # Sensitivity along null directions, relative to the output's own gradient.
        along = np.abs(g @ null_dirs) if null_dirs.size else np.zeros((g.shape[0], 0))
        size = np.linalg.norm(g / d, axis=1)
        if along.size:
            on_null = np.any(along > 1e-6 * np.maximum(size, 1e-300)[:, None], axis=1)
        else:
            on_null = np.zeros(g.shape[0], bool)
        if name == "weights":
            vague = std > WEIGHT_VAGUE
        elif name == "correction":
            vague = std > np.maximum(np.abs(val), correction_ref)
        elif name in SCALED_BLOCKS:
            # 0 (no fall-off, no shift) is a value like any other; only a null
            # direction leaves a coefficient undetermined.
            vague = np.zeros(val.shape, bool)
        else:
            vague = std > np.abs(val)
        if name in LOG_BLOCKS and name in layout:
            # Held at LOG_LIMIT: bounded by the data, not measured (past it, g is 0
            # and the standard error would come out 0).
            vague = vague | (np.abs(z[slice(*layout[name])]) >= LOG_LIMIT)
        bad = on_null | vague | ~np.isfinite(std)
        shape = np.shape(value)
        stderr[name] = np.where(bad, np.nan, std).reshape(shape)
        undetermined[name] = bad.reshape(shape)
    nuisance_stderr = None
    if q:
        last = np.arange(p - q, p)
        var = np.maximum(np.diag(cov_theta), np.diag(cov_blocks))[last]
        on_null = np.any(np.abs(null_dirs[last]) > 1e-6, axis=1) if null_dirs.size else np.zeros(q, bool)
        nuisance_stderr = np.where(on_null, np.nan, np.sqrt(np.maximum(var, 0.0)))
    linear = {"jacobians": {k: np.asarray(jacs[k]).reshape(-1, p) for k in values}, "cov": cov_theta,
              "cov_blocks": cov_blocks, "null_dirs": null_dirs, "scale": d}
    return Uncertainty(stderr, undetermined, float(np.sqrt(sigma2)) * float(objective.scale), dof,
                       nuisance_stderr, linear)


def _coinciding(natural, scales, flags, msgs, roles):
    """Gaussians whose layers differ by a blur far below a pixel (docs/model.md, section 6: two
    Gaussians with equal variance): only the sum of their weights is determined.

    Neighbours in variance that coincide form one group, with one message: a chain of three
    is one sum, not two overlapping ones."""
    v = np.asarray(natural["variances"], np.float64)
    s_max = scales.max_stretch(float(natural["sss_level"]), float(natural["correction"]), float(natural["maxdd"]))
    order = np.argsort(v)
    w = np.asarray(natural["weights"])
    groups = []
    for a, b in zip(order[:-1], order[1:]):
        if s_max * np.sqrt(v[b] - v[a]) >= COINCIDENT_PX:
            continue
        if groups and groups[-1][-1] == a:
            groups[-1].append(b)
        else:
            groups.append([a, b])
    for group in groups:
        gap_px = s_max * np.sqrt(np.max(np.diff(v[group])))  # the group is in ascending order
        flag = flags.setdefault("weights", np.zeros(w.shape, bool))
        flag[group] = True
        if roles["variances"] == "free":
            vflag = flags.setdefault("variances", np.zeros(v.shape, bool))
            vflag[group] = True
        total = np.round(np.atleast_1d(sum(w[i] for i in group)), 4).tolist()
        names = ", ".join(f"weights[{i}]" for i in group)
        listed = [f"{v[i]:.4g}" for i in group]
        if len(group) == 2:
            spread = f"variances {listed[0]} and {listed[1]} differ by a blur of {gap_px:.2f} px at most"
        else:
            spread = (f"variances {', '.join(listed[:-1])} and {listed[-1]} differ from one to the next "
                      f"by a blur of {gap_px:.2f} px at most")
        msgs.append(f"{names}: {spread} (below {COINCIDENT_PX} px), so only their sum "
                    f"{total if len(total) > 1 else total[0]} is determined")


def structural_reasons(
    roles: dict, model: str, scales, natural: dict, weights, active, correction_stderr=None
) -> tuple[dict, list]:
    """Undetermined entries for the reasons docs/model.md, section 6 names, with messages.

    ``maxdd`` acts through the kink of ``min(|dd|, maxdd)``: a Gauss-Newton standard
    error only sees the pixels next to the kink, so the extremes are checked by
    counting. With fewer than :data:`FEW_SLOPES` of the masked slopes above
    ``maxdd`` it is only bounded below; with fewer below it, only
    ``correction * maxdd`` is determined. A correction within two standard errors
    of 0 makes ``maxdd`` unmeasurable too.

    Returns ``(flags, messages)``: ``flags[name]`` is a boolean array of the
    parameter's shape (True = undetermined).
    """
    flags, msgs = {}, []
    slopes = scales.slopes
    for name, role in roles.items():
        if role == "unused":
            flags[name] = np.ones(np.shape(natural[name]), bool)
            msgs.append(f"{name}: not used by the {model!r} model, so the data cannot determine it")
    if roles["correction"] == "free" or roles["maxdd"] == "free":
        delta = float(natural["maxdd"])
        c = float(natural["correction"])
        above = float(np.mean(slopes > delta))
        below = float(np.mean(slopes < delta))
        if np.all(slopes == 0):
            for k in ("correction", "maxdd"):
                if roles[k] == "free":
                    flags[k] = np.ones((), bool)
            msgs.append("correction, maxdd: the depth is flat on the mask, so they have no effect")
        elif roles["maxdd"] == "free" and above < FEW_SLOPES:
            flags["maxdd"] = np.ones((), bool)
            msgs.append(
                f"maxdd: {above:.1%} of the masked depth slopes reach it (the largest is "
                f"{slopes.max():.4g}), so it is only bounded below; larger values give the same image"
            )
        elif roles["maxdd"] == "free" and below < FEW_SLOPES:
            flags["maxdd"] = np.ones((), bool)
            if roles["correction"] == "free":
                flags["correction"] = np.ones((), bool)
            msgs.append(
                f"correction, maxdd: {1 - below:.1%} of the masked depth slopes exceed maxdd, so only "
                f"their product correction*maxdd = {c * delta:.4g} is determined"
            )
        elif (
            roles["maxdd"] == "free"
            and correction_stderr is not None
            and np.isfinite(correction_stderr)
            and c < 2.0 * correction_stderr
        ):
            flags["maxdd"] = np.ones((), bool)
            msgs.append(
                f"maxdd: the correction ({c:.3g} +- {correction_stderr:.2g}) is consistent with 0, "
                "so maxdd has no measurable effect"
            )
    if roles["weights"] in ("linear", "free"):
        _coinciding(natural, scales, flags, msgs, roles)
    if roles["variances"] == "free" and weights is not None:
        w = np.asarray(weights)
        w = w if w.ndim == 2 else w[:, None]
        zero = np.all((w < ZERO_WEIGHT) | (np.asarray(active) == 0), axis=1)
        if np.any(zero):
            flags["variances"] = zero
            idx = ", ".join(str(i) for i in np.flatnonzero(zero))
            msgs.append(f"variances[{idx}]: the weight is ~0, so the variance has no effect")
        _unresolved(natural, scales, flags, msgs, ~zero)
    return flags, msgs


def _unresolved(natural, scales, flags, msgs, weighted):
    """Estimated variances the image cannot resolve: a Gaussian narrower than
    :data:`UNRESOLVED_PX` even where the stretch is largest looks like no blur, and
    one wider than the mask even where the stretch is smallest looks like a flat
    offset; either way its variance can wander without changing the image."""
    v = np.asarray(natural["variances"], np.float64)
    args = (float(natural["sss_level"]), float(natural["correction"]), float(natural["maxdd"]))
    low, high = scales.stretch_range(*args)
    widest, narrowest = high * np.sqrt(v), low * np.sqrt(v)
    narrow = weighted & (widest < UNRESOLVED_PX)
    wide = weighted & (narrowest > scales.mask_diameter)
    for chosen, what in ((narrow, f"blurs by less than {UNRESOLVED_PX} px even where the stretch is largest, "
                                  "so it cannot be told from no blur"),
                         (wide, f"blurs by more than the mask's width ({scales.mask_diameter:.0f} px) even "
                                "where the stretch is smallest, so it cannot be told from a flat offset")):
        if np.any(chosen):
            flag = flags.setdefault("variances", np.zeros(v.shape, bool))
            flag |= chosen
            which = np.flatnonzero(chosen)
            idx = ", ".join(str(i) for i in which)
            values = ", ".join(f"{x:.3g}" for x in v[which])
            msgs.append(f"variances[{idx}] ({values} mm^2): {what}")
