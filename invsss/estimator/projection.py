"""Variable projection: the linear unknowns eliminated by weighted least squares.

For fixed nonlinear parameters the prediction of target channel ``j`` of pair ``p``,

    pred_pj = r_pj * sum_i beta_ij X_pi[..., j] + b_pj,

is linear in ``beta`` (gains, or gain times weight for the ``sog`` layers) and in the
per-pair offsets ``b``. For each channel the ``(nb + P)``-square normal equations
are solved in closed form (Golub & Pereyra's variable projection): the residual
handed to the nonlinear solver is the one at the optimal linear unknowns, and it
stays differentiable because ``jnp.linalg.solve`` is.

Conditioning: the normal matrix is scaled to unit diagonal before solving (the
layers of neighbouring variances are strongly correlated) and a ridge of
``1e-10`` on that unit diagonal keeps an exactly collinear basis (two equal
variances, or an ``L`` so small that every layer equals the source) finite: the
ridge then splits the coefficient evenly, which the uncertainty analysis reports
as undetermined.

``active`` switches basis images off (coefficient exactly 0): the estimator's
active-set step for weights the unconstrained solution makes negative.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

__all__ = ["RIDGE", "solve_linear", "combine"]

RIDGE = 1e-10


def combine(
    basis: Float[Array, "nb H W C"], ratio: Float[Array, " C"], coef: Float[Array, "nb C"], offset: Float[Array, " C"]
) -> Float[Array, "H W C"]:
    """``r * sum_i coef_i X_i + b``: the prediction of one pair."""
    return ratio * jnp.einsum("ihwc,ic->hwc", basis, coef) + offset


def solve_linear(
    bases: tuple,
    targets: tuple,
    weights: tuple,
    ratios: Float[Array, "P C"],
    active: Float[Array, "nb C"],
) -> tuple[Float[Array, "nb C"], Float[Array, "P C"]]:
    """Weighted least-squares coefficients and offsets shared by all pairs.

    Parameters
    ----------
    bases : tuple of arrays, shape (nb, H_p, W_p, C)
        Basis images of each pair.
    targets, weights : tuples of arrays, shape (H_p, W_p, C)
        Targets and per-pixel weights (mask times robust weight; 0 = ignored).
    ratios : array, shape (P, C)
        Gain of pair p relative to pair 0 (row 0 is 1).
    active : array, shape (nb, C)
        1 for basis images in use (per channel), 0 for those held at a zero coefficient.

    Returns
    -------
    coef : array, shape (nb, C)
    offset : array, shape (P, C)
    """
    nb, c = bases[0].shape[0], bases[0].shape[-1]
    p = len(bases)
    n = nb + p
    gram = jnp.zeros((c, n, n), bases[0].dtype)
    rhs = jnp.zeros((c, n), bases[0].dtype)
    for k, (x, t, w) in enumerate(zip(bases, targets, weights)):
        x = x * ratios[k]
        wx = x * w
        cross = jnp.einsum("ihwc,jhwc->cij", wx, x)
        ones = jnp.einsum("ihwc->ci", wx)
        gram = gram.at[:, :nb, :nb].add(cross)
        gram = gram.at[:, :nb, nb + k].set(ones)
        gram = gram.at[:, nb + k, :nb].set(ones)
        gram = gram.at[:, nb + k, nb + k].set(jnp.sum(w, axis=(0, 1)))
        rhs = rhs.at[:, :nb].add(jnp.einsum("ihwc,hwc->ci", wx, t))
        rhs = rhs.at[:, nb + k].set(jnp.sum(w * t, axis=(0, 1)))
    on = jnp.concatenate([active, jnp.ones((p, c), active.dtype)]).T  # (C, n)
    gram = gram * on[:, :, None] * on[:, None, :]
    rhs = rhs * on
    # Jacobi scaling; an inactive or all-zero column keeps scale 1 (the double
    # `where` keeps the derivative of the unused branch finite).
    diag = jnp.diagonal(gram, axis1=1, axis2=2)
    usable = diag > 1e-200
    scale = jnp.where(usable, jnp.sqrt(jnp.where(usable, diag, 1.0)), 1.0)
    scaled = gram / (scale[:, :, None] * scale[:, None, :])
    # Inactive rows become identity rows with a zero right-hand side.
    scaled = scaled + jnp.eye(n) * (RIDGE + (1.0 - on))[:, :, None]
    sol = jnp.linalg.solve(scaled, (rhs / scale)[..., None])[..., 0] / scale
    return sol[:, :nb].T, sol[:, nb:].T
