"""Fit Jensen's dipole to a measured radial profile: ``R(r) -> (sigma_s', sigma_a)``.

The dipole's falloff with distance fixes the effective transport coefficient
``sigma_tr = sqrt(3 sigma_a sigma_t')`` and its absolute level fixes the albedo
``sigma_s' / sigma_t'``, so an *absolute* profile (in mm^-2: a measurement divided
by the spot's area, see :func:`invsss.measure_profile`) determines both
coefficients. The fit minimises the difference of logarithms, so the faint tail
counts as much as the bright centre, over ``log sigma`` so both stay positive.
Concrete data only: NumPy and SciPy, not JAX.
"""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np

from ..forward.profiles import jensen_dipole
from ..validation import InvalidInputError, positive_number

__all__ = ["DipoleFit", "fit_dipole"]

#: Coarse start grid, mm^-1: wide enough for skin in the visible and NIR.
_START_SIGMA_S = np.geomspace(0.05, 20.0, 15)
_START_SIGMA_A = np.geomspace(1e-4, 2.0, 15)


class DipoleFit(eqx.Module):
    """Dipole coefficients that best reproduce a measured profile.

    Attributes
    ----------
    sigma_s_prime, sigma_a : ndarray, shape () or (C,)
        Reduced scattering and absorption coefficients, mm^-1.
    eta : float
        Relative index of refraction assumed by the fit.
    rms_log_error : ndarray, shape () or (C,)
        Root mean square of ``log(model) - log(measured)`` at the samples (0.1 is
        about 10 % per sample).
    """

    sigma_s_prime: np.ndarray
    sigma_a: np.ndarray
    eta: float = eqx.field(static=True)
    rms_log_error: np.ndarray = eqx.field(default=None)

    def to_dict(self) -> dict:
        """JSON-ready: ``sigma_s_prime``, ``sigma_a`` (mm^-1), ``eta``, ``rms_log_error``."""
        number = lambda a: np.asarray(a).tolist()  # noqa: E731
        return {"sigma_s_prime": number(self.sigma_s_prime), "sigma_a": number(self.sigma_a),
                "eta": float(self.eta), "rms_log_error": number(self.rms_log_error)}


def _dipole(r, log_sigma, eta):
    s, a = np.exp(log_sigma)
    return np.asarray(jensen_dipole(r, s, a, eta), dtype=np.float64)


def _fit_channel(r, y, eta):
    from scipy.optimize import least_squares

    log_y = np.log(y)

    def residual(log_sigma):
        return np.log(_dipole(r, log_sigma, eta)) - log_y

    # The dipole is smooth but the loss has long flat valleys: start from the
    # best point of a coarse grid, evaluated in one vectorised call per row.
    best, best_cost = None, np.inf
    for s in _START_SIGMA_S:
        model = np.asarray(jensen_dipole(r, s, _START_SIGMA_A, eta))  # (N, grid)
        with np.errstate(divide="ignore"):  # an underflowed tail is just a bad start
            cost = np.sum((np.log(model) - log_y[:, None]) ** 2, axis=0)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best, best_cost = np.log([s, _START_SIGMA_A[k]]), cost[k]
    solution = least_squares(residual, best, method="lm", x_scale=1.0, xtol=1e-12, ftol=1e-12)
    sigma_s, sigma_a = np.exp(solution.x)
    return sigma_s, sigma_a, float(np.sqrt(np.mean(solution.fun**2)))


def fit_dipole(r_mm, reflectance, eta: float = 1.3) -> DipoleFit:
    """Fit ``sigma_s'`` and ``sigma_a`` of :func:`invsss.jensen_dipole` to ``R(r)`` samples.

    Parameters
    ----------
    r_mm : array, shape (N,)
        Distances from the spot centre, mm, N >= 3.
    reflectance : array, shape (N,) or (N, C)
        Absolute ``R(r)`` in mm^-2 (divide a measurement by the spot area:
        ``measure_profile(..., spot_area_mm2=lit_area_mm2)``), > 0; each channel is
        fitted on its own.
    eta : float
        Relative index of refraction of the medium (1.3 for skin).

    Returns
    -------
    DipoleFit

    Raises
    ------
    InvalidInputError
        Fewer than 3 samples, mismatched shapes, or values that are not finite and > 0.

    Examples
    --------
    >>> import numpy as np
    >>> from invsss.forward.profiles import jensen_dipole
    >>> r = np.linspace(1.0, 8.0, 30)
    >>> fit = fit_dipole(r, np.asarray(jensen_dipole(r, 1.2, 0.05)))
    >>> round(float(fit.sigma_s_prime), 3), round(float(fit.sigma_a), 4)
    (1.2, 0.05)
    """
    r = np.asarray(r_mm, dtype=np.float64)
    y = np.asarray(reflectance, dtype=np.float64)
    if r.ndim != 1 or r.size < 3:
        raise InvalidInputError(f"r_mm: expected at least 3 distances in a 1-D array, got shape {r.shape}")
    if y.shape[:1] != r.shape or y.ndim > 2:
        raise InvalidInputError(
            f"reflectance: expected shape ({r.size},) or ({r.size}, C) like r_mm, got {y.shape}"
        )
    if not (np.all(np.isfinite(r)) and np.all(r >= 0)):
        raise InvalidInputError("r_mm: expected finite distances >= 0")
    if not (np.all(np.isfinite(y)) and np.all(y > 0)):
        raise InvalidInputError("reflectance: expected finite values > 0 (the fit is in log space)")
    eta = positive_number(eta, "eta")
    columns = y[:, None] if y.ndim == 1 else y
    # float64: in float32 the far tail underflows and the solver's finite
    # differences drown in rounding.
    with jax.enable_x64(True):
        fits = np.array([_fit_channel(r, columns[:, c], eta) for c in range(columns.shape[1])])
    pick = (lambda a: a[0]) if y.ndim == 1 else (lambda a: a)  # noqa: E731
    return DipoleFit(pick(fits[:, 0]), pick(fits[:, 1]), eta, pick(fits[:, 2]))
