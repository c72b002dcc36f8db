"""Read a medium's ``sigma_s'`` and ``sigma_a`` from a measured profile, with standard errors.

Any model of :data:`invsss.measurement.profile_models.PROFILE_MODELS` is fitted to
``R(r)`` samples by least squares on ``log R`` over ``log sigma`` (both coefficients
stay positive, and every decade of the falloff counts alike). Where the samples come
with standard errors (:attr:`invsss.MeasuredProfile.reflectance_stderr`) each
residual is divided by its relative error, and the coefficients' covariance is
``(J^T J)^-1`` from the exact Jacobian (JAX) times the reduced chi-square when that
is above 1, so a model that misses the samples by more than their noise reports a
wider uncertainty rather than a false precision. Without standard errors the
residuals' own scatter is the noise. Burley's ``d`` and surface albedo ``A`` of the
fitted medium are reported with their propagated errors (the engines' profiles are
Burley's). Concrete data: NumPy and SciPy around JAX models.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..validation import InvalidInputError
from .profile_models import PROFILE_MODELS, burley_parameters

__all__ = ["MediumFit", "fit_medium", "MODEL_NAMES"]

MODEL_NAMES = tuple(PROFILE_MODELS)
_START_SIGMA_S = np.geomspace(0.05, 20.0, 25)
_START_SIGMA_A = np.geomspace(1e-4, 2.0, 25)


class MediumFit(eqx.Module):
    """A medium read from a profile, per channel (shape () for one channel, (C,) for C).

    Attributes
    ----------
    sigma_s_prime, sigma_a, sigma_s_prime_stderr, sigma_a_stderr : ndarray
        Coefficients and their standard errors, mm^-1.
    burley_d, burley_albedo, burley_d_stderr, burley_albedo_stderr : ndarray
        Burley's shape parameter (mm) and surface albedo of the fitted medium
        (searchlight configuration, or diffuse for ``model="burley-diffuse"``).
    rms_log_error : ndarray
        RMS of ``log(model) - log(R)`` at the samples (0.1 is about 10 %).
    reduced_chi2 : ndarray
        Weighted residual sum over (samples - 2); about 1 when the model matches the
        samples within their noise (NaN without standard errors).
    model : str
        The profile model's name.
    eta : float
        The relative index given to the model.
    """

    sigma_s_prime: np.ndarray
    sigma_a: np.ndarray
    sigma_s_prime_stderr: np.ndarray
    sigma_a_stderr: np.ndarray
    burley_d: np.ndarray
    burley_albedo: np.ndarray
    burley_d_stderr: np.ndarray
    burley_albedo_stderr: np.ndarray
    rms_log_error: np.ndarray
    reduced_chi2: np.ndarray
    model: str = eqx.field(static=True)
    eta: float = eqx.field(static=True)

    def to_dict(self) -> dict:
        """JSON-ready: every attribute, arrays as lists."""
        out = {}
        for name in ("sigma_s_prime", "sigma_a", "sigma_s_prime_stderr", "sigma_a_stderr",
                     "burley_d", "burley_albedo", "burley_d_stderr", "burley_albedo_stderr",
                     "rms_log_error", "reduced_chi2"):
            out[name] = np.asarray(getattr(self, name)).tolist()
        return {"model": self.model, "eta": float(self.eta), **out}


def _log_model(model, r, eta):
    def f(log_sigma):
        s, a = jnp.exp(log_sigma)
        return jnp.log(model(r, s, a, eta))
    return f


def _starts(model, r, log_y, eta, weights, count=3):
    """The ``count`` best points of a coarse grid (one vectorised call per row of sigma_s')."""
    costs = np.full((_START_SIGMA_S.size, _START_SIGMA_A.size), np.inf)
    for i, s in enumerate(_START_SIGMA_S):
        with np.errstate(divide="ignore", invalid="ignore"):
            values = np.asarray(model(r, s, _START_SIGMA_A, eta), np.float64)  # (N, grid)
            cost = np.sum(((np.log(values) - log_y[:, None]) * weights[:, None]) ** 2, axis=0)
        costs[i] = np.where(np.isfinite(cost), cost, np.inf)
    best = np.argsort(costs, axis=None)[:count]
    return [np.log([_START_SIGMA_S[k // costs.shape[1]], _START_SIGMA_A[k % costs.shape[1]]])
            for k in best]


def _burley_of(log_sigma, illumination):
    s, a = jnp.exp(log_sigma)
    A, d = burley_parameters(s, a, illumination)
    return jnp.stack([d, A])


def _fit_channel(model_name, r, y, stderr, eta):
    from scipy.optimize import least_squares

    model = PROFILE_MODELS[model_name]
    log_y = np.log(y)
    weighted = stderr is not None
    weights = y / stderr if weighted else np.ones_like(y)
    log_model = jax.jit(_log_model(model, r, eta))
    jacobian = jax.jit(jax.jacfwd(_log_model(model, r, eta)))

    def residual(p):
        return (np.asarray(log_model(p)) - log_y) * weights

    def jac(p):
        return np.asarray(jacobian(p)) * weights[:, None]

    # The loss has long curved valleys with side minima (a dipole can trade a tenfold
    # sigma_s' for a lower albedo): polish the three best grid points, keep the best.
    solution = min((least_squares(residual, start, jac=jac, method="lm", xtol=1e-12, ftol=1e-12)
                    for start in _starts(model, r, log_y, eta, weights)), key=lambda s: s.cost)
    p, res, J = solution.x, solution.fun, jac(solution.x)
    dof = max(r.size - 2, 1)
    chi2 = float(res @ res) / dof
    # Weighted: inflate by a misfit beyond the noise; unweighted: the scatter is the noise.
    scale = max(chi2, 1.0) if weighted else chi2
    cov = np.linalg.pinv(J.T @ J) * scale  # of log sigma
    sigma = np.exp(p)
    sigma_err = sigma * np.sqrt(np.clip(np.diag(cov), 0.0, None))
    illumination = "diffuse" if "-diffuse" in model_name else "searchlight"
    burley = np.asarray(_burley_of(jnp.asarray(p), illumination))
    b_jac = np.asarray(jax.jacfwd(_burley_of)(jnp.asarray(p), illumination))
    burley_err = np.sqrt(np.clip(np.diag(b_jac @ cov @ b_jac.T), 0.0, None))
    rms = float(np.sqrt(np.mean((np.asarray(log_model(p)) - log_y) ** 2)))
    return (*sigma, *sigma_err, *burley, *burley_err, rms, chi2 if weighted else np.nan)


def _check(r_mm, reflectance, stderr, model, eta):
    r = np.asarray(r_mm, dtype=np.float64)
    y = np.asarray(reflectance, dtype=np.float64)
    if model not in PROFILE_MODELS:
        raise InvalidInputError(f"model: expected one of {', '.join(MODEL_NAMES)}, got {model!r}")
    if r.ndim != 1 or r.size < 3:
        raise InvalidInputError(f"r_mm: expected at least 3 distances in a 1-D array, got shape {r.shape}")
    if not (np.all(np.isfinite(r)) and np.all(r > 0)):
        raise InvalidInputError("r_mm: expected finite distances > 0")
    if y.shape[:1] != r.shape or y.ndim > 2:
        raise InvalidInputError(f"reflectance: expected shape ({r.size},) or ({r.size}, C) like r_mm, got {y.shape}")
    if not (np.all(np.isfinite(y)) and np.all(y > 0)):
        raise InvalidInputError("reflectance: expected finite values > 0 (the fit is in log space)")
    if stderr is not None:
        stderr = np.asarray(stderr, dtype=np.float64)
        if stderr.shape != y.shape or not (np.all(np.isfinite(stderr)) and np.all(stderr > 0)):
            raise InvalidInputError(f"stderr: expected finite values > 0 of shape {y.shape} like reflectance")
    try:
        eta = float(eta)
    except (TypeError, ValueError):
        eta = float("nan")
    if not (np.isfinite(eta) and eta >= 1.0):
        raise InvalidInputError(f"eta: expected a finite number >= 1, got {eta!r}")
    try:  # the transport models have tables for some boundaries only
        PROFILE_MODELS[model](np.ones(1), 1.0, 0.1, eta)
    except ValueError as error:
        raise InvalidInputError(f"{error} (model {model})") from None
    return r, y, stderr, eta


def fit_medium(r_mm, reflectance, *, model: str = "transport", eta: float = 1.3, stderr=None) -> MediumFit:
    """Fit ``sigma_s'`` and ``sigma_a`` of a profile model to ``R(r)`` samples.

    Parameters
    ----------
    r_mm : array, shape (N,)
        Distances from the spot centre, mm (> 0, N >= 3): only the trusted ones
        (:func:`invsss.measurement.trusted_radii.trusted_radii`).
    reflectance : array, shape (N,) or (N, C)
        Absolute ``R(r)`` in mm^-2 (> 0); each channel is fitted on its own.
    model : str
        One of :data:`MODEL_NAMES`: ``"transport"`` (what a camera on the axis of a
        focused spot reads, tabulated from the exact transport), ``"transport-diffuse"``
        (the same for a Lambertian source on the surface), ``"burley"`` (Burley's
        searchlight fit), ``"burley-diffuse"``, ``"photon-beam"``, ``"better-dipole"``
        or ``"dipole"``. The published models give the exitance, not the camera's
        reading (module :mod:`invsss.measurement.transport_profile`).
    eta : float
        Relative index of refraction (>= 1), for the dipole models.
    stderr : array like ``reflectance``, optional
        Standard errors of the samples (> 0); they weight the fit and set the
        reported uncertainties.

    Returns
    -------
    MediumFit

    Raises
    ------
    InvalidInputError
        An unknown model, fewer than 3 samples, mismatched shapes, or values that are
        not finite and > 0.

    Examples
    --------
    >>> import numpy as np
    >>> from invsss.measurement.profile_models import burley_searchlight
    >>> r = np.linspace(1.5, 6.0, 20)
    >>> fit = fit_medium(r, np.asarray(burley_searchlight(r, 0.8, 0.03)), model="burley")
    >>> round(float(fit.sigma_s_prime), 3), round(float(fit.sigma_a), 4)
    (0.8, 0.03)
    """
    r, y, stderr, eta = _check(r_mm, reflectance, stderr, model, eta)
    columns = y[:, None] if y.ndim == 1 else y
    errors = None if stderr is None else (stderr[:, None] if stderr.ndim == 1 else stderr)
    with jax.enable_x64(True):
        fits = np.array([
            _fit_channel(model, r, columns[:, c], None if errors is None else errors[:, c], eta)
            for c in range(columns.shape[1])
        ])
    pick = (lambda a: a[0]) if y.ndim == 1 else (lambda a: a)  # noqa: E731
    arrays = [f.name for f in dataclasses.fields(MediumFit)][:10]  # the fields before model and eta
    return MediumFit(**{name: pick(fits[:, k]) for k, name in enumerate(arrays)}, model=model, eta=eta)
