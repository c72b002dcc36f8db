"""The tabulated camera reading: its nodes, its scaling with the mean free path, and the transport."""

import jax
import numpy as np
import pytest

from invsss.measurement import transport_table
from invsss.measurement.transport_profile import TRANSPORT_ETAS, transport_reading

RHO = np.asarray(transport_table.RHO)
ONE_MINUS_ALPHA = np.asarray(transport_table.ONE_MINUS_ALPHA)


def test_the_table_nodes_are_read_exactly():
    table = np.asarray(transport_table.LOG_READING[("searchlight", 1.3, 0.0)])
    i, j = 7, np.arange(10, 40, 3)
    alpha = 1.0 - ONE_MINUS_ALPHA[i]
    with jax.enable_x64(True):
        # sigma_t = 1: r is rho, sigma_s' = alpha, sigma_a = 1 - alpha.
        values = np.asarray(transport_reading(RHO[j], alpha, 1.0 - alpha, 1.3))
    np.testing.assert_allclose(np.log(values), table[i, j], atol=1e-9)


def test_lengths_scale_with_the_mean_free_path():
    # A medium k times denser reads k^2 T(k r): the same profile in mean free paths.
    r = np.linspace(1.5, 6.0, 7)
    with jax.enable_x64(True):
        base = np.asarray(transport_reading(r, 0.7748, 0.02808, 1.0))
        dense = np.asarray(transport_reading(r / 2.0, 2 * 0.7748, 2 * 0.02808, 1.0))
    np.testing.assert_allclose(dense, 4.0 * base, rtol=1e-10)


def test_the_reading_is_continuous_across_albedo_cells():
    # Catmull-Rom in log(1 - alpha): no jump where one cell meets the next.
    node = ONE_MINUS_ALPHA[9]
    with jax.enable_x64(True):
        below, above = (np.asarray(transport_reading(3.0, 1.0 - m, m, 1.3)) for m in (node * (1 - 1e-9),
                                                                                     node * (1 + 1e-9)))
    np.testing.assert_allclose(below, above, rtol=1e-6)


def test_only_the_tabulated_boundaries_are_read():
    assert 1.0 in TRANSPORT_ETAS and 1.3 in TRANSPORT_ETAS
    with pytest.raises(ValueError, match="^eta: the transport model has tables for eta"):
        transport_reading(3.0, 0.8, 0.03, 1.4)


def _camera_reading_monte_carlo(sigma_s, sigma_a, edges, photons, seed):
    """A second, minimal Monte Carlo (no boundary, pencil beam along the normal, the
    reading estimated at every collision from its depth), for the check below."""
    rng = np.random.default_rng(seed)
    sigma_t = sigma_s + sigma_a
    tally = np.zeros(edges.size - 1)
    pos = np.zeros((photons, 3))
    direction = np.tile([0.0, 0.0, 1.0], (photons, 1))  # z is the depth
    weight = np.ones(photons)
    while weight.size:
        pos = pos + direction * (-np.log(rng.random(weight.size)) / sigma_t)[:, None]
        inside = pos[:, 2] > 0.0
        pos, weight = pos[inside], weight[inside]
        r = np.hypot(pos[:, 0], pos[:, 1])
        tally += np.histogram(r, edges, weights=weight * sigma_s / sigma_t * np.exp(-sigma_t * pos[:, 2]))[0]
        weight = weight * sigma_s / sigma_t
        cos = 2.0 * rng.random(weight.size) - 1.0
        phi = 2.0 * np.pi * rng.random(weight.size)
        sin = np.sqrt(1.0 - cos**2)
        direction = np.stack([sin * np.cos(phi), sin * np.sin(phi), cos], axis=1)
        alive = weight > 1e-3
        pos, direction, weight = pos[alive], direction[alive], weight[alive]
    # pi L: pi times the sum over 4 pi, over the ring area pi (b^2 - a^2), per photon.
    return tally / (4.0 * np.pi * photons * (edges[1:] ** 2 - edges[:-1] ** 2))


@pytest.mark.slow
def test_the_table_is_the_transport_of_an_independent_monte_carlo():
    # The thesis's medium, no boundary, 1.5 to 5 mm: within the check's own noise (1 %)
    # and the truncated walk's bias (weights below 1e-3 are dropped: under 1 %).
    edges = np.linspace(1.5, 5.0, 8)
    reading = _camera_reading_monte_carlo(0.7748, 0.02808, edges, 150_000, seed=5)
    with jax.enable_x64(True):
        r = np.linspace(1.5, 5.0, 701)
        model = np.asarray(transport_reading(r, 0.7748, 0.02808, 1.0))
    # The model's ring average over each bin.
    ring = np.array([np.trapezoid((model * r)[(r >= a) & (r <= b)], r[(r >= a) & (r <= b)]) * 2 / (b**2 - a**2)
                     for a, b in zip(edges[:-1], edges[1:])])
    np.testing.assert_allclose(reading, ring, rtol=0.03)
