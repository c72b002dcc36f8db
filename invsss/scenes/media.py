"""Scattering media for path-traced scenes: named presets and their coefficients.

A medium is a homogeneous, isotropically scattering volume with reduced scattering
``sigma_s'`` and absorption ``sigma_a`` in 1/mm (one value, or one per RGB channel)
inside a boundary of relative index ``eta``. With an isotropic phase function the
path tracer's scattering coefficient is ``sigma_s'`` itself, which is what the
dipole (:func:`invsss.forward.profiles.jensen_dipole`) is written in.

The presets:

``thesis-940``
    The thesis measured a 940 nm profile on the inner forearm but published only its
    sum-of-Gaussians fit (Table 5.1, :data:`invsss.forward.profiles.THESIS_NIR_940`), not
    coefficients. The numbers here are the Jensen dipole (eta 1.3, the value the
    thesis uses for skin) fitted to that profile by least squares on ``r R(r)`` for
    ``r`` in [0.05, 8] mm (:func:`dipole_fit_to_thesis_profile` reproduces them). They
    land next to Jensen's red skin1 channel (0.74, 0.032), which agrees with the
    thesis's remark that its 940 nm profile is close to red light's.
``jensen-skin1``
    Jensen et al. 2001's measured skin1, per RGB channel
    (:data:`invsss.forward.profiles.JENSEN_SKIN1`).
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from ..forward.profiles import JENSEN_SKIN1, THESIS_NIR_940

__all__ = ["MEDIUM_PRESETS", "dipole_fit_to_thesis_profile"]

#: Named media: ``sigma_s_prime`` and ``sigma_a`` in 1/mm, ``eta``, and where they come from.
MEDIUM_PRESETS = MappingProxyType(
    {
        "thesis-940": MappingProxyType(
            {
                "sigma_s_prime": 0.7748,
                "sigma_a": 0.02808,
                "eta": 1.3,
                "source": "Jensen dipole (eta 1.3) least-squares fit to the thesis's 940 nm "
                "sum-of-Gaussians profile (Table 5.1), r R(r) on r in [0.05, 8] mm",
            }
        ),
        "jensen-skin1": MappingProxyType(
            {
                "sigma_s_prime": list(JENSEN_SKIN1["sigma_s_prime"]),
                "sigma_a": list(JENSEN_SKIN1["sigma_a"]),
                "eta": JENSEN_SKIN1["eta"],
                "source": JENSEN_SKIN1["source"],
            }
        ),
    }
)


def dipole_fit_to_thesis_profile(r_max: float = 8.0, num: int = 200) -> tuple[float, float]:
    """``(sigma_s', sigma_a)`` in 1/mm of the dipole closest to the thesis's 940 nm profile.

    Minimises ``sum (r (R_dipole(r) - R_thesis(r)))^2`` over ``r`` in ``[0.05, r_max]``
    mm, with ``eta = 1.3``; the ``r`` weight is the ring area each radius stands
    for, so the fit matches energy rather than the peak at ``r = 0``.

    Examples
    --------
    >>> s, a = dipole_fit_to_thesis_profile()
    >>> round(s, 3), round(a, 4)
    (0.775, 0.0281)
    """
    # Imported here: only this derivation needs SciPy's solver and the JAX profile code.
    from scipy.optimize import least_squares

    from ..forward.profiles import jensen_dipole

    variances = np.asarray(THESIS_NIR_940["variances"])
    weights = np.asarray(THESIS_NIR_940["weights"])
    r = np.linspace(0.05, r_max, num)
    measured = np.sum(weights * np.exp(-(r[:, None] ** 2) / (2 * variances)) / (2 * np.pi * variances), axis=1)

    def residual(log_coefficients):
        sigma_s_prime, sigma_a = np.exp(log_coefficients)
        return r * (np.asarray(jensen_dipole(r, sigma_s_prime, sigma_a, 1.3), np.float64) - measured)

    # Log coefficients keep both positive; the start is Jensen's red skin1 channel.
    # JAX computes in float32: a finite-difference step of 1e-8 would see no change.
    solution = least_squares(residual, np.log([0.74, 0.032]), diff_step=1e-3)
    sigma_s_prime, sigma_a = np.exp(solution.x)
    return float(sigma_s_prime), float(sigma_a)
