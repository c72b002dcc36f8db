"""Fit a sum of Gaussians to any sampled radial profile (thesis 4.1.3).

The thesis fitted its measured 940 nm profile with MATLAB's curve fitting tool; this
module does the same job with :class:`optimistix.LevenbergMarquardt`, stepped by the
estimator's :func:`~invsss.estimator.solve.run_solver` (one way to solve in the
package), for one channel
or for several channels sharing their variances (d'Eon & Luebke's RGB skin fit).

The model ``R(r) = sum_i w_i G(v_i, r)`` is linear in the weights, so the fit is a
separable least-squares problem, solved by variable projection (Golub & Pereyra):
Levenberg-Marquardt runs over ``log v`` only, and for every trial of variances the
weights are the exact non-negative least-squares solution (per channel, or shared).
Eliminating the weights removes the strongest coupling of the problem, makes the fit
independent of a weight start, and gives exact zeros for superfluous Gaussians
(d'Eon's table has several) instead of a parameter drifting toward ``log w = -inf``.

Log variances keep ``v > 0`` and make every variance equally easy to move over the
decades a skin profile spans. Starts spread the variances geometrically over the
radii that hold the profile's energy, with different spreads; the lowest final loss
wins.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from ..estimator.solve import run_solver
from ..forward.profiles import SumOfGaussians, gaussian
from ..validation import InvalidInputError

__all__ = ["WEIGHTINGS", "RELATIVE_ERROR_FLOOR", "MAX_GAUSSIANS", "ProfileFit", "fit_sum_of_gaussians"]

#: Residual weightings :func:`fit_sum_of_gaussians` accepts by name.
WEIGHTINGS = ("r", "relative", "none")
#: Samples below this fraction of their channel's peak are left out of
#: :attr:`ProfileFit.max_relative_error`.
RELATIVE_ERROR_FLOOR = 1e-3
#: The exact non-negative weights try all 2^K subsets of Gaussians (1024 at K = 10,
#: each a K-column solve): cheap up to here, and published skin fits use at most 6.
MAX_GAUSSIANS = 10


class ProfileFit(eqx.Module):
    """A fitted :class:`~invsss.SumOfGaussians` and how well it fits.

    Attributes
    ----------
    profile : SumOfGaussians
        The fit, Gaussians in increasing variance; weights (K,) or (K, C).
    rms : scalar
        ``||s (fit - R)|| / ||s R||`` with the fit's sample weights ``s``: the weighted
        residual relative to the weighted data (0 is perfect).
    max_relative_error : scalar
        ``max |fit - R| / R`` over the samples with a non-zero weight and ``R`` at least
        ``RELATIVE_ERROR_FLOOR`` (1e-3) of its channel's peak: below that a profile is
        invisible next to its peak, and a relative error of a value that underflows
        toward 0 says nothing.
    converged : bool scalar
        Whether the final Levenberg-Marquardt stage met its tolerance.
    num_steps : int scalar
        Solver steps of the winning start, both stages.
    weighting : str
        The weighting used (``"custom"`` for an array).
    """

    profile: SumOfGaussians
    rms: Float[Array, ""]
    max_relative_error: Float[Array, ""]
    converged: Bool[Array, ""]
    num_steps: Int[Array, ""]
    weighting: str = eqx.field(static=True, default="r")

    def to_dict(self) -> dict:
        """The JSON profile format with the diagnostics under ``"fit"``."""
        d = self.profile.to_dict()
        d["fit"] = {
            "weighting": self.weighting,
            "rms": float(self.rms),
            "max_relative_error": float(self.max_relative_error),
            "converged": bool(self.converged),
            "num_steps": int(self.num_steps),
        }
        return d


# --------------------------------------------------------------------------- core


def _design(log_v, r, sample_weights):
    # (C, N, K): the weighted Gaussians, one design matrix per channel.
    g = gaussian(jnp.exp(log_v), r[:, None])
    return sample_weights[:, :, None] * g[None]


def _linear_weights(a, b, ridge):
    # Least-squares weights for one design a (M, K) and data b (M,). Columns are
    # normalised first, and a ridge row per column keeps the QR full rank when two
    # variances coincide, a Gaussian has no support on the samples, or a column is
    # masked to zero (its weight is then exactly 0). QR rather than the normal
    # equations: it keeps float32 usable and has a clean JVP.
    k = a.shape[1]
    norms = jnp.sqrt(jnp.maximum(jnp.sum(a**2, axis=0), jnp.finfo(a.dtype).tiny))
    a_aug = jnp.concatenate([a / norms, jnp.sqrt(ridge) * jnp.eye(k, dtype=a.dtype)])
    b_aug = jnp.concatenate([b, jnp.zeros((k,), b.dtype)])
    q, upper = jnp.linalg.qr(a_aug)
    return jsl.solve_triangular(upper, q.T @ b_aug) / norms


def _subset_masks(k: int) -> np.ndarray:
    # Every subset of the K Gaussians (the empty one included), as (2^K, K) 0/1 rows.
    codes = np.arange(2**k)
    return ((codes[:, None] >> np.arange(k)) & 1).astype(np.float64)


def _nonnegative_weights(a, b, ridge, masks):
    """Non-negative least squares ``min ||a w - b||, w >= 0``, exactly.

    When the unconstrained solution is non-negative it is the answer (the usual case
    near a good fit). Otherwise every subset of Gaussians is tried: the NNLS solution
    is the unconstrained solution on its set of positive weights and is feasible, so
    among the subsets whose unconstrained solution is non-negative the one with the
    least residual is it (the empty subset, w = 0, is always feasible). With
    K <= MAX_GAUSSIANS that is at most 1024 tiny solves, exact and branch-free. The
    subset is chosen without gradients and only its solve is differentiated: the
    variable-projection Jacobian on the active set, which is locally constant.
    """
    a_c, b_c = jax.lax.stop_gradient(a), jax.lax.stop_gradient(b)

    def best_subset(_):
        candidates = jax.vmap(lambda m: _linear_weights(a_c * m, b_c, ridge))(masks)  # (S, K)
        losses = jnp.sum((candidates @ a_c.T - b_c) ** 2, axis=1)
        feasible = jnp.all(candidates >= 0, axis=1)
        return masks[jnp.argmin(jnp.where(feasible, losses, jnp.inf))]

    unconstrained_ok = jnp.all(_linear_weights(a_c, b_c, ridge) >= 0)
    mask = jax.lax.cond(unconstrained_ok, lambda _: masks[-1], best_subset, None)
    return _linear_weights(a * mask, b, ridge)


def _group(a, b, per_channel):
    # Shared weights: stack every channel's rows into one problem.
    if per_channel:
        return a, b
    c, n, k = a.shape
    return a.reshape(1, c * n, k), b.reshape(1, c * n)


def _weights_for(log_v, args):
    r, b, sample_weights, per_channel, ridge, masks = args
    a, bb = _group(_design(log_v, r, sample_weights), b, per_channel)
    # lax.map (a scan) over channels rather than vmap: under vmap the cond in
    # _nonnegative_weights would run both branches; a Python loop would compile one
    # copy per channel.
    w = jax.lax.map(lambda ab: _nonnegative_weights(ab[0], ab[1], ridge, masks), (a, bb))
    return a, bb, w


def _projected_residual(log_v, args):
    a, bb, w = _weights_for(log_v, args)
    return jnp.einsum("cmk,ck->cm", a, w) - bb


class _ProjectedResidual(eqx.Module):
    """The variable-projection residual over ``log v`` as the solver's objective.

    The data are fields (traced arrays), so every start of one problem shape
    reuses the compiled solver step.
    """

    r: Array
    b: Array
    sample_weights: Array
    ridge: Array
    masks: Array
    per_channel: bool = eqx.field(static=True)

    @property
    def args(self):
        return (self.r, self.b, self.sample_weights, self.per_channel, self.ridge, self.masks)

    def __call__(self, log_v, args=None):
        return _projected_residual(log_v, self.args).ravel(), None


@eqx.filter_jit
def _weights_and_loss(problem, log_v):
    a, bb, w = _weights_for(log_v, problem.args)
    loss = jnp.sum((jnp.einsum("cmk,ck->cm", a, w) - bb) ** 2)
    return w, jnp.where(jnp.isfinite(loss), loss, jnp.inf)


def _fit_from(log_v_start, problem, solver, max_steps):
    """Variable projection from one start: ``(log v, w (C', K), loss, converged, steps)``.

    Stepped by :func:`invsss.estimator.solve.run_solver`, the package's one way
    to run a solver (its step compiles once per problem shape and serves every
    start).
    """
    record = run_solver(solver, problem, log_v_start, max_steps)
    w, loss = _weights_and_loss(problem, record.z)
    return record.z, w, loss, record.converged, record.steps


# --------------------------------------------------------------------------- starts


def _energy_radii(r, y):
    # Radii holding 2 % and 98 % of the ring energy 2 pi r R(r) dr of all channels.
    energy = np.abs(y).sum(axis=1) * r
    cumulative = np.concatenate([[0.0], np.cumsum(0.5 * (energy[1:] + energy[:-1]) * np.diff(r))])
    if cumulative[-1] <= 0:
        return r[r > 0].min(), r.max()
    cumulative /= cumulative[-1]
    return np.interp(0.02, cumulative, r), np.interp(0.98, cumulative, r)


def _initial_log_variances(r, y, num_gaussians, num_starts, variance_range):
    # For one Gaussian of variance v the ring energy's 2 % and 98 % radii are 0.20 sqrt(v)
    # and 2.8 sqrt(v) (Rayleigh quantiles), so these radii bracket the variances.
    if variance_range is None:
        r_lo, r_hi = _energy_radii(r, y)
        r_lo = max(r_lo, 0.5 * np.min(np.diff(r)), 1e-12)
        lo, hi = np.log((r_lo / 0.20) ** 2), np.log((max(r_hi, r_lo) / 2.8) ** 2)
    else:
        lo, hi = np.log(variance_range[0]), np.log(variance_range[1])
    centre, half = 0.5 * (lo + hi), max(0.5 * (hi - lo), np.log(2.0))
    spreads = np.linspace(1.5, 0.6, num_starts) if num_starts > 1 else np.ones(1)
    shifts = np.linspace(-0.5, 0.5, num_starts) * half if num_starts > 1 else np.zeros(1)
    ticks = np.linspace(-1.0, 1.0, num_gaussians) if num_gaussians > 1 else np.zeros(1)
    starts = centre + spreads[:, None] * half * ticks[None, :]
    if num_gaussians == 1:
        starts = starts + shifts[:, None]
    return starts


# --------------------------------------------------------------------------- API


def _is_count(n) -> bool:
    return isinstance(n, (int, np.integer)) and not isinstance(n, bool) and bool(n >= 1)


def _check_inputs(r, profile, num_gaussians, weighting, num_starts, max_steps, variance_range):
    r = np.asarray(r, dtype=np.float64)
    y = np.asarray(profile, dtype=np.float64)
    if r.ndim != 1 or r.size < 2:
        raise InvalidInputError(f"r: expected a 1-D array of at least 2 radii, got shape {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r < 0) or np.any(np.diff(r) <= 0):
        raise InvalidInputError("r: expected finite, non-negative, strictly increasing radii")
    if y.ndim not in (1, 2) or y.shape[0] != r.size:
        raise InvalidInputError(
            f"profile: expected shape ({r.size},) or ({r.size}, C) to match r, got {y.shape}",
            field="profile",
        )
    if not np.all(np.isfinite(y)):
        raise InvalidInputError("profile: contains NaN or infinite values", field="profile")
    if not np.any(y > 0):
        raise InvalidInputError("profile: has no positive value to fit", field="profile")
    if not _is_count(num_gaussians):
        raise InvalidInputError(f"num_gaussians: expected an integer >= 1, got {num_gaussians!r}")
    if num_gaussians > MAX_GAUSSIANS:
        raise InvalidInputError(
            f"num_gaussians: at most {MAX_GAUSSIANS} Gaussians are supported, got {num_gaussians}"
        )
    if r.size < 2 * num_gaussians:
        raise InvalidInputError(
            f"r: {num_gaussians} Gaussians need at least {2 * num_gaussians} samples, got {r.size}"
        )
    if not _is_count(num_starts):
        raise InvalidInputError(f"num_starts: expected an integer >= 1, got {num_starts!r}")
    if not _is_count(max_steps):
        raise InvalidInputError(f"max_steps: expected an integer >= 1, got {max_steps!r}", field="max_steps")
    if isinstance(weighting, str):
        if weighting not in WEIGHTINGS:
            raise InvalidInputError(
                f"weighting: expected one of {', '.join(WEIGHTINGS)} or an array, got {weighting!r}"
            )
    else:
        try:
            s = np.asarray(weighting, dtype=np.float64)
        except (TypeError, ValueError):
            s = np.full(1, np.nan)
        if s.shape not in ((r.size,), y.shape) or not np.all(np.isfinite(s)) or np.any(s < 0):
            raise InvalidInputError(
                f"weighting: expected finite non-negative sample weights of shape ({r.size},) "
                f"or {y.shape}"
            )
    if variance_range is not None:
        vr = np.asarray(variance_range, dtype=np.float64)
        if vr.shape != (2,) or not np.all(np.isfinite(vr)) or not 0 < vr[0] <= vr[1]:
            raise InvalidInputError(
                f"variance_range: expected (low, high) with 0 < low <= high, got {variance_range!r}"
            )
    return r, y


def _sample_weights(weighting, r, y):
    # (N, C) weights on the residual fit - R.
    if isinstance(weighting, str):
        if weighting == "r":
            return np.broadcast_to(r[:, None], y.shape)
        if weighting == "relative":
            positive = y > 0
            return np.where(positive, 1.0 / np.where(positive, y, 1.0), 0.0)
        return np.ones_like(y)
    s = np.asarray(weighting, dtype=np.float64)
    return np.broadcast_to(s[:, None] if s.ndim == 1 else s, y.shape)


def fit_sum_of_gaussians(
    r,
    profile,
    num_gaussians: int = 4,
    *,
    weights_per_channel: bool = True,
    weighting="r",
    variance_range=None,
    num_starts: int = 4,
    max_steps: int = 256,
    rtol: float | None = None,
    atol: float | None = None,
    source: str = "sum-of-Gaussians fit",
) -> ProfileFit:
    """Fit ``R(r) ~ sum_i w_i G(v_i, r)`` to a sampled radial profile (thesis 4.1.3).

    Parameters
    ----------
    r : array, shape (N,)
        Strictly increasing radii, mm (>= 0).
    profile : array, shape (N,) or (N, C)
        ``R(r)``, mm^-2 (or the thesis's normalised intensities), one column per channel.
    num_gaussians : int
        K, the number of Gaussians (1 to MAX_GAUSSIANS = 10; at least 2K samples).
    weights_per_channel : bool
        For C > 1: True fits shared variances with one weight per Gaussian and channel
        (weights (K, C), as d'Eon & Luebke's RGB table); False fits one weight vector
        (K,) to all channels at once. Ignored for a 1-D profile (weights (K,)).
    weighting : {"r", "relative", "none"} or array, shape (N,) or (N, C)
        Weight on the residual ``fit - R`` per sample. ``"r"`` (default) fits
        ``r R(r)``: the ring energy ``2 pi r R(r) dr`` is what a profile contributes to
        an image and to its total reflectance, and skin profiles span decades, so an
        unweighted fit would match the peak at ``r = 0`` only while ``r R`` stays
        within one or two decades over the useful range (and is finite even for
        Burley's ``1/r`` peak). ``"relative"`` fits ``(fit - R) / R``: every decade
        counts equally, good for the tail, but it chases noise where ``R`` is tiny.
        ``"none"`` is the plain residual. The residual is per sample: for unevenly
        spaced radii, fold the spacing into an array weighting.
    variance_range : (float, float), optional
        Bracket, mm^2, for the starting variances; by default from the radii holding
        2 % and 98 % of the ring energy.
    num_starts : int
        Starts with different geometric spreads of the variances; the best one wins.
    max_steps : int
        Levenberg-Marquardt steps per stage.
    rtol, atol : float, optional
        Solver tolerances (on the data scaled to a unit maximum). Defaults depend on
        the dtype: 1e-8 / 1e-10 in float64, 1e-4 / 1e-6 in float32.
    source : str
        Stored in the returned profile.

    Returns
    -------
    ProfileFit
        ``.profile`` (Gaussians by increasing variance) and the fit diagnostics.

    Raises
    ------
    InvalidInputError
        Bad shapes or values of any argument.

    Notes
    -----
    This is a boundary function on concrete data (it validates values and picks the
    best start in Python), not something to trace. Each distinct problem shape (N, C,
    K, shared or per-channel weights) compiles once, a few seconds; later calls with
    the same shape take milliseconds. ``converged`` False usually means more
    Gaussians than the data support: one escapes toward a huge variance (a constant
    offset) or a tiny one (a spike); fit fewer.

    Examples
    --------
    >>> import jax.numpy as jnp
    >>> import invsss
    >>> r = jnp.linspace(0.0, 6.0, 61)
    >>> truth = invsss.SumOfGaussians(jnp.array([0.3, 0.7]), jnp.array([0.2, 2.0]))
    >>> fit = invsss.fit_sum_of_gaussians(r, truth(r), num_gaussians=2)
    >>> [round(v, 2) for v in fit.profile.variances.tolist()]
    [0.2, 2.0]
    """
    r_np, y_np = _check_inputs(
        r, profile, num_gaussians, weighting, num_starts, max_steps, variance_range
    )
    dtype = jnp.result_type(float)  # float64 under jax.enable_x64, float32 otherwise
    low_precision = jnp.finfo(dtype).bits < 64
    rtol = (1e-4 if low_precision else 1e-8) if rtol is None else float(rtol)
    atol = (1e-6 if low_precision else 1e-10) if atol is None else float(atol)

    one_channel = y_np.ndim == 1
    y2 = y_np[:, None] if one_channel else y_np
    per_channel = bool(weights_per_channel) and not one_channel
    s2 = _sample_weights(weighting, r_np, y2)
    weighted = s2 * y2
    scale = float(np.max(np.abs(weighted)))
    if scale <= 0:
        raise InvalidInputError("weighting: gives zero weight to every positive profile sample")

    log_v0 = _initial_log_variances(r_np, y2, int(num_gaussians), int(num_starts), variance_range)
    problem = _ProjectedResidual(
        jnp.asarray(r_np, dtype),
        jnp.asarray(weighted.T / scale, dtype),
        jnp.asarray(s2.T, dtype),
        jnp.asarray(100.0 * jnp.finfo(dtype).eps, dtype),
        jnp.asarray(_subset_masks(int(num_gaussians)), dtype),
        per_channel,
    )
    solver: optx.LevenbergMarquardt = optx.LevenbergMarquardt(rtol=rtol, atol=atol, norm=optx.rms_norm)
    results = [_fit_from(jnp.asarray(start, dtype), problem, solver, int(max_steps)) for start in log_v0]
    log_v, w, _, converged, steps = min(results, key=lambda result: float(result[2]))
    variances = jnp.exp(log_v)
    # (K, C') with C' = C or 1; where() turns the -0.0 of a masked weight into 0.0.
    weights = jnp.where(w > 0, w * scale, 0.0).T
    if one_channel or not per_channel:
        weights = weights[:, 0]
    fitted = SumOfGaussians(weights, variances, source).sorted()

    values = np.asarray(fitted(jnp.asarray(r_np, dtype)), dtype=np.float64)
    values = values[:, None] if values.ndim == 1 else values
    values = np.broadcast_to(values, y2.shape)
    residual = s2 * (values - y2)
    rms = np.sqrt(np.sum(residual**2) / np.sum(weighted**2))
    usable = (y2 >= RELATIVE_ERROR_FLOOR * y2.max(axis=0)) & (y2 > 0) & (s2 > 0)
    max_rel = np.max(np.abs(values - y2)[usable] / y2[usable]) if np.any(usable) else np.nan
    return ProfileFit(
        profile=fitted,
        rms=jnp.asarray(rms, dtype),
        max_relative_error=jnp.asarray(max_rel, dtype),
        converged=jnp.asarray(converged),
        num_steps=jnp.asarray(steps),
        weighting=weighting if isinstance(weighting, str) else "custom",
    )
