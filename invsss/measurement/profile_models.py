"""Published models of the profile a small spot makes on a thick medium: ``R(r)`` from its coefficients.

A spot of light on a semi-infinite, isotropically scattering medium (reduced
coefficients ``sigma_s'`` and ``sigma_a``, mm^-1, relative index ``eta``) lights the
surface around it with a radial profile ``R(r)`` in mm^-2 (per unit power that
entered). :func:`invsss.forward.profiles.jensen_dipole` is the classical answer. Its
level is wrong where a spot measurement looks, 1 to 6 mm from the spot: a
path-traced slab of the thesis's 940 nm medium lies 25-37 % below it there
(``experiments/profile_slab.py``), and a dipole fit turns that level into a wrong
albedo. The models here are the published alternatives:

``burley``
    Christensen & Burley 2015, "Approximate Reflectance Profiles for Efficient
    Subsurface Scattering" (Pixar Technical Memo 15-04): the normalized diffusion
    ``A (e^{-r/d} + e^{-r/3d}) / (8 pi d r)`` fitted to Monte Carlo transport, with
    ``d = l / s(A)``, ``l = 1 / sigma_t`` the mean free path and ``s`` their fitted
    scaling factor: ``s = 1.85 - A + 7 |A - 0.8|^3`` for a searchlight (light entering
    perpendicularly at a point, their section 5) and ``s = 1.9 - A + 3.5 (A - 0.8)^2``
    for diffuse surface transmission (section 6). The surface albedo ``A`` and the
    single-scattering albedo ``alpha = sigma_s' / sigma_t`` are tied by the fit
    ``alpha = 1 - exp(-5.09406 A + 2.61188 A^2 - 4.31805 A^3)`` published with the
    model for production path tracing (Chiang, Kutz & Burley 2016, "Practical and
    Controllable Subsurface Scattering for Production Path Tracing"); it is inverted
    here in closed form (the cubic is increasing, so it has one real root).
``better_dipole``
    d'Eon 2012, "A Better Dipole": Grosjean's diffusion coefficient
    ``D = (2 sigma_a + sigma_s') / (3 sigma_t'^2)``, the extrapolated boundary
    ``z_b = 2 A D`` with ``A = (1 + 3 C2) / (1 - 2 C1)`` from the Fresnel moments
    ``C_n = int_0^1 F(mu) mu^n dmu`` of the inner boundary, and the exitance
    ``C_phi phi + C_E E`` from both the fluence and the flux of the dipole,
    ``C_phi = (1 - 2 C1) / 4``, ``C_E = (1 - 3 C2) / 2``. One source at ``1 / sigma_t'``.
``photon_beam``
    Habel, Christensen & Jarosz 2013, "Photon Beam Diffusion": the same dipole
    kernel integrated along the refracted beam, sources ``sigma_s' e^{-sigma_t' t}``
    at every depth ``t``, each weighted by their near-surface correction
    ``kappa = 1 - exp(-2 sigma_t' (d_r + t))`` (Gauss-Laguerre quadrature, 64 nodes).
    Single scattering is left out: a camera on the spot's axis sees none of it beyond
    the spot's edge, which is where the measurement samples.

All are pure JAX functions of the coefficients (differentiable, usable under
``jax.jit``); the Fresnel moments are a fixed midpoint quadrature of the exact
unpolarised Fresnel reflectance, so ``eta`` may be traced too.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..forward.profiles import burley as _burley_profile
from ..forward.profiles import jensen_dipole
from .transport_profile import transport_diffuse, transport_diffuse_rough, transport_searchlight

__all__ = [
    "ILLUMINATIONS",
    "PROFILE_MODELS",
    "burley_scaling",
    "burley_alpha",
    "burley_albedo",
    "burley_medium",
    "burley_parameters",
    "burley_searchlight",
    "burley_diffuse",
    "fresnel_moments",
    "point_source_exitance",
    "better_dipole",
    "photon_beam",
]

#: Burley's two configurations of the light: a perpendicular spot, or light that came
#: through the surface from every direction (a Lambertian source on the surface).
ILLUMINATIONS = ("searchlight", "diffuse")

# alpha = 1 - exp(-(c1 A + c2 A^2 + c3 A^3)), Chiang, Kutz & Burley 2016.
_ALBEDO_FIT = (5.09406, -2.61188, 4.31805)
_MU_NODES = 2048
_LAGUERRE = np.polynomial.laguerre.laggauss(64)


def burley_scaling(A, illumination: str = "searchlight"):
    """Burley's scaling factor ``s(A)``: ``d = l / s`` with ``l = 1 / sigma_t`` (mm).

    ``"searchlight"``: ``1.85 - A + 7 |A - 0.8|^3``; ``"diffuse"``:
    ``1.9 - A + 3.5 (A - 0.8)^2`` (Christensen & Burley 2015, sections 5 and 6).
    """
    A = jnp.asarray(A)
    if illumination == "searchlight":
        return 1.85 - A + 7.0 * jnp.abs(A - 0.8) ** 3
    if illumination == "diffuse":
        return 1.9 - A + 3.5 * (A - 0.8) ** 2
    raise ValueError(f"illumination: expected one of {', '.join(ILLUMINATIONS)}, got {illumination!r}")


def burley_alpha(A):
    """Single-scattering albedo ``alpha`` of the medium whose surface albedo is ``A``."""
    A = jnp.asarray(A)
    c1, c2, c3 = _ALBEDO_FIT
    return 1.0 - jnp.exp(-(c1 * A + c2 * A**2 + c3 * A**3))


def burley_albedo(alpha):
    """Inverse of :func:`burley_alpha`: the surface albedo ``A`` of albedo ``alpha`` in [0, 1).

    ``c3 A^3 + c2 A^2 + c1 A = -log(1 - alpha)`` has one real root (its derivative
    ``c1 + 2 c2 A + 3 c3 A^2`` has no real zero), found with Cardano's formula.

    Examples
    --------
    >>> round(float(burley_albedo(burley_alpha(0.6))), 6)
    0.6
    """
    c1, c2, c3 = _ALBEDO_FIT
    y = -jnp.log1p(-jnp.asarray(alpha))
    b, c = c2 / c3, c1 / c3  # monic: A^3 + b A^2 + c A - y / c3 = 0
    p = c - b * b / 3.0
    q = 2.0 * b**3 / 27.0 - b * c / 3.0 - y / c3
    root = jnp.sqrt(q * q / 4.0 + p**3 / 27.0)  # p > 0: always real
    return jnp.cbrt(-q / 2.0 + root) + jnp.cbrt(-q / 2.0 - root) - b / 3.0


def burley_medium(A, d, illumination: str = "searchlight"):
    """``(sigma_s', sigma_a)`` in mm^-1 of Burley's surface albedo ``A`` and shape ``d`` (mm)."""
    A, d = jnp.asarray(A), jnp.asarray(d)
    sigma_t = 1.0 / (d * burley_scaling(A, illumination))
    alpha = burley_alpha(A)
    return alpha * sigma_t, (1.0 - alpha) * sigma_t


def burley_parameters(sigma_s_prime, sigma_a, illumination: str = "searchlight"):
    """Burley's ``(A, d)`` of a medium: the inverse of :func:`burley_medium`.

    Examples
    --------
    >>> A, d = burley_parameters(0.7748, 0.02808)
    >>> round(float(A), 3), round(float(d), 3)
    (0.644, 1.011)
    """
    sigma_s_prime, sigma_a = jnp.asarray(sigma_s_prime), jnp.asarray(sigma_a)
    sigma_t = sigma_s_prime + sigma_a
    A = burley_albedo(sigma_s_prime / sigma_t)
    return A, 1.0 / (sigma_t * burley_scaling(A, illumination))


def burley_searchlight(r, sigma_s_prime, sigma_a, eta=None):
    """Burley's searchlight profile of a medium, mm^-2 (``eta`` is ignored: the fit has its own)."""
    A, d = burley_parameters(sigma_s_prime, sigma_a, "searchlight")
    return _burley_profile(r, d, A)


def burley_diffuse(r, sigma_s_prime, sigma_a, eta=None):
    """Burley's diffuse-transmission profile of a medium, mm^-2 (``eta`` ignored)."""
    A, d = burley_parameters(sigma_s_prime, sigma_a, "diffuse")
    return _burley_profile(r, d, A)


# --------------------------------------------------------------------------- dipoles


def _fresnel_inside(cos_i, eta):
    # Unpolarised reflectance of light meeting the boundary from inside (index eta
    # relative to outside); 1 beyond the critical angle.
    sin2_t = eta**2 * (1.0 - cos_i**2)
    cos_t = jnp.sqrt(jnp.clip(1.0 - sin2_t, 0.0, None))
    rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    return jnp.where(sin2_t >= 1.0, 1.0, 0.5 * (rs**2 + rp**2))


def fresnel_moments(eta):
    """``(C1, C2)``: ``C_n = int_0^1 F(mu) mu^n dmu`` of the boundary seen from inside.

    ``2 C1`` is the internal diffuse Fresnel reflectance (0.44 at ``eta = 1.3``; 0 at 1).

    Examples
    --------
    >>> c1, c2 = fresnel_moments(1.0)
    >>> float(c1), float(c2)
    (0.0, 0.0)
    """
    eta = jnp.asarray(eta, dtype=jnp.result_type(float))
    mu = (jnp.arange(_MU_NODES) + 0.5) / _MU_NODES
    f = _fresnel_inside(mu[:, None], eta.reshape(-1)[None, :])
    c1 = jnp.mean(f * mu[:, None], axis=0).reshape(eta.shape)
    c2 = jnp.mean(f * mu[:, None] ** 2, axis=0).reshape(eta.shape)
    return c1, c2


def point_source_exitance(r, depth, sigma_s_prime, sigma_a, eta=1.3):
    """Exitance at ``r`` (mm^-2) of a unit isotropic source at ``depth`` mm (d'Eon 2012's dipole).

    The arguments broadcast against each other; :func:`better_dipole` is ``alpha'``
    times this at ``depth = 1 / sigma_t'``, :func:`photon_beam` its integral along the beam.
    """
    sigma_t = sigma_s_prime + sigma_a
    diffusion = (2.0 * sigma_a + sigma_s_prime) / (3.0 * sigma_t**2)
    sigma_tr = jnp.sqrt(sigma_a / diffusion)
    c1, c2 = fresnel_moments(eta)
    z_b = 2.0 * diffusion * (1.0 + 3.0 * c2) / (1.0 - 2.0 * c1)
    z_v = -depth - 2.0 * z_b
    d_r = jnp.sqrt(r**2 + depth**2)
    d_v = jnp.sqrt(r**2 + z_v**2)
    decay_r, decay_v = jnp.exp(-sigma_tr * d_r), jnp.exp(-sigma_tr * d_v)
    fluence = (decay_r / d_r - decay_v / d_v) / (4.0 * jnp.pi * diffusion)
    flux = (depth * (1.0 + sigma_tr * d_r) * decay_r / d_r**3
            - z_v * (1.0 + sigma_tr * d_v) * decay_v / d_v**3) / (4.0 * jnp.pi)
    return 0.25 * (1.0 - 2.0 * c1) * fluence + 0.5 * (1.0 - 3.0 * c2) * flux


def _broadcast(r, *coefficients):
    # r (*N) against coefficients (*C): (*N, *C), as jensen_dipole.
    coefficients = [jnp.asarray(c, dtype=jnp.result_type(float)) for c in coefficients]
    shape = jnp.broadcast_shapes(*(c.shape for c in coefficients))
    r = jnp.asarray(r, dtype=jnp.result_type(float))
    return r.reshape(r.shape + (1,) * len(shape)), [jnp.broadcast_to(c, shape) for c in coefficients]


def better_dipole(r, sigma_s_prime, sigma_a, eta=1.3):
    """d'Eon 2012's dipole: one source of strength ``alpha'`` at ``1 / sigma_t'``, mm^-2."""
    r, (s, a, eta) = _broadcast(r, sigma_s_prime, sigma_a, eta)
    sigma_t = s + a
    return s / sigma_t * point_source_exitance(r, 1.0 / sigma_t, s, a, eta)


def photon_beam(r, sigma_s_prime, sigma_a, eta=1.3):
    """Photon beam diffusion's multiple scattering (Habel et al. 2013), mm^-2.

    ``R(r) = int_0^inf sigma_s' e^{-sigma_t' t} kappa(t) R_t(r) dt`` with ``R_t`` the
    dipole kernel of a unit source at depth ``t``; in ``u = sigma_t' t`` that is
    ``alpha' int e^{-u} kappa R_t du``, a Gauss-Laguerre sum.
    """
    r, (s, a, eta) = _broadcast(r, sigma_s_prime, sigma_a, eta)
    sigma_t = s + a
    nodes, weights = (jnp.asarray(x, dtype=r.dtype) for x in _LAGUERRE)
    extra = (1,) * r.ndim
    depth = nodes.reshape((-1,) + extra) / sigma_t
    value = point_source_exitance(r[None], depth, s, a, eta)
    kappa = 1.0 - jnp.exp(-2.0 * sigma_t * (jnp.sqrt(r[None] ** 2 + depth**2) + depth))
    return s / sigma_t * jnp.tensordot(weights, kappa * value, axes=1)


#: Models by name: ``f(r, sigma_s', sigma_a, eta) -> R(r)`` in mm^-2. The published
#: ones give the exitance; ``transport``, ``transport-diffuse`` and ``transport-diffuse-rough``
#: give what a camera on the spot's axis reads (:mod:`invsss.measurement.transport_profile`).
PROFILE_MODELS = {
    "transport": transport_searchlight,
    "transport-diffuse": transport_diffuse,
    "transport-diffuse-rough": transport_diffuse_rough,
    "burley": burley_searchlight,
    "burley-diffuse": burley_diffuse,
    "photon-beam": photon_beam,
    "better-dipole": better_dipole,
    "dipole": jensen_dipole,
}
