"""What a camera on the spot's axis reads around a spot: the exact transport, tabulated.

Every published profile model (:mod:`invsss.measurement.profile_models`) gives the
exitance, the power leaving per unit area in all directions. A camera looking down
on the spot reads the radiance along the normal, ``pi L(r)``, which is the exitance
only for a Lambertian surface. Around a spot it is not: for the thesis's 940 nm
medium without a boundary ``pi L`` is 0.76 of the exitance at 1.3 mm, 0.92 at 3.3 mm
and 1.01 at 6.2 mm (the light near the spot leaves obliquely, far away it leaves
mostly along the normal), so a fit of any exitance model misreads the medium.

This model is the camera's reading itself, from a Monte Carlo of the transport
(``experiments/searchlight_transport.py``, which writes
:mod:`invsss.measurement.transport_table`): a semi-infinite, isotropically scattering
medium with a smooth boundary of relative index ``eta`` (1.0 or 1.3 tabulated), lit
at a point by a pencil beam along the normal (``"searchlight"``: a focused spot
light, as in the thesis) or by light from all directions (``"diffuse"``: a
Lambertian source on the surface), per unit incident power; and the diffuse case
through a rough boundary (Beckmann 0.5, Walter et al. 2007's microfacet refraction, the
default boundary of the path-traced scenes). Lengths scale with the
mean free path: a medium of extinction ``sigma_t = sigma_s' + sigma_a`` and albedo
``alpha = sigma_s' / sigma_t`` reads ``sigma_t^2 T_alpha(sigma_t r)``. The table is
interpolated linearly in ``log(sigma_t r)`` and with Catmull-Rom cubics in
``log(1 - alpha)`` (albedos 0.4 to 0.997), ``log T`` throughout; outside the table
the edge cells are extended linearly. Pure JAX, differentiable.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from . import transport_table, transport_table_rough

__all__ = ["TRANSPORT_ETAS", "transport_reading", "transport_searchlight", "transport_diffuse",
           "transport_diffuse_rough"]

_LOG_RHO = np.log(np.asarray(transport_table.RHO))
_LOG_ONE_MINUS_ALPHA = np.log(np.asarray(transport_table.ONE_MINUS_ALPHA))
# Keys (incidence, eta, Beckmann roughness of the boundary; 0 smooth).
_TABLES = {(key + (0.0,))[:3]: np.asarray(rows) for module in (transport_table, transport_table_rough)
           for key, rows in module.LOG_READING.items()}
assert all(np.allclose(m.RHO, transport_table.RHO) and np.allclose(m.ONE_MINUS_ALPHA, transport_table.ONE_MINUS_ALPHA)
           for m in (transport_table_rough,)), "the transport tables must share their grid"
#: The boundaries tabulated: relative indices of refraction.
TRANSPORT_ETAS = tuple(sorted({eta for _, eta, _ in _TABLES}))


def _cell(grid, x):
    # Index of the cell holding x (edge cells extended) and the position in it.
    grid = jnp.asarray(grid)
    i = jnp.clip(jnp.searchsorted(grid, x) - 1, 0, grid.size - 2)
    return i, (x - grid[i]) / (grid[i + 1] - grid[i])


def _catmull_rom(p0, p1, p2, p3, t):
    return p1 + 0.5 * t * (p2 - p0 + t * (2 * p0 - 5 * p1 + 4 * p2 - p3 + t * (3 * (p1 - p2) + p3 - p0)))


def _table(incidence, eta, roughness):
    try:
        eta = float(eta)
    except TypeError:
        raise ValueError("eta: the transport model needs a concrete eta (one of its tables)") from None
    for (name, tabulated, rough), table in _TABLES.items():
        if name == incidence and abs(tabulated - eta) < 1e-6 and abs(rough - roughness) < 1e-6:
            return table
    have = ", ".join(f"{e:g}" for n, e, g in _TABLES if n == incidence and abs(g - roughness) < 1e-6)
    raise ValueError(f"eta: the transport model has tables for eta {have or 'none'} ({incidence}, "
                     f"roughness {roughness:g}), got {eta:g}")


def transport_reading(r, sigma_s_prime, sigma_a, eta=1.3, incidence: str = "searchlight",
                      roughness: float = 0.0):
    """The camera's reading ``pi L(r)`` in mm^-2 per unit incident power.

    Parameters
    ----------
    r : array, shape (*N)
        Distance from the spot, mm (> 0).
    sigma_s_prime, sigma_a : float or array, shape (*C)
        Reduced scattering and absorption, mm^-1; arrays add trailing axes.
    eta : float
        Relative index of the boundary: one of :data:`TRANSPORT_ETAS`.
    incidence : {"searchlight", "diffuse"}
        How the light enters.
    roughness : float
        Beckmann roughness of the boundary: 0 (smooth) or a tabulated one (0.5, diffuse).

    Returns
    -------
    array, shape (*N, *C)
    """
    table = jnp.asarray(_table(incidence, eta, roughness))
    s, a = jnp.asarray(sigma_s_prime, dtype=jnp.result_type(float)), jnp.asarray(sigma_a, dtype=jnp.result_type(float))
    shape = jnp.broadcast_shapes(s.shape, a.shape)
    r = jnp.asarray(r, dtype=s.dtype)
    r = r.reshape(r.shape + (1,) * len(shape))
    sigma_t = s + a
    log_rho = jnp.log(r * sigma_t)
    u = jnp.log(a / sigma_t) * jnp.ones_like(log_rho)
    grid_u, grid_rho = _LOG_ONE_MINUS_ALPHA, _LOG_RHO
    # The albedo grid decreases in 1 - alpha: search it reversed.
    i_rev, t_u = _cell(grid_u[::-1], u)
    i = grid_u.size - 2 - i_rev  # cell [i, i + 1] in the stored order, t from i + 1 to i
    j, t_r = _cell(grid_rho, log_rho)

    def row(k):
        k = jnp.clip(k, 0, grid_u.size - 1)
        return table[k, j] * (1.0 - t_r) + table[k, j + 1] * t_r

    # Stored order runs to smaller 1 - alpha; in increasing u the nodes are i+2, i+1, i, i-1.
    p0, p1, p2, p3 = row(i + 2), row(i + 1), row(i), row(i - 1)
    # Extend the end cells linearly rather than with the clipped cubic.
    inside = (i + 2 <= grid_u.size - 1) & (i - 1 >= 0) & (t_u >= 0) & (t_u <= 1)
    linear = p1 + (p2 - p1) * t_u
    log_t = jnp.where(inside, _catmull_rom(p0, p1, p2, p3, t_u), linear)
    return sigma_t**2 * jnp.exp(log_t)


def transport_searchlight(r, sigma_s_prime, sigma_a, eta=1.3):
    """:func:`transport_reading` of a focused spot (pencil beam along the normal)."""
    return transport_reading(r, sigma_s_prime, sigma_a, eta, "searchlight")


def transport_diffuse(r, sigma_s_prime, sigma_a, eta=1.3):
    """:func:`transport_reading` of a Lambertian source on the surface."""
    return transport_reading(r, sigma_s_prime, sigma_a, eta, "diffuse")


def transport_diffuse_rough(r, sigma_s_prime, sigma_a, eta=1.3):
    """:func:`transport_reading` of a Lambertian source through a rough boundary (Beckmann 0.5)."""
    return transport_reading(r, sigma_s_prime, sigma_a, eta, "diffuse", 0.5)
