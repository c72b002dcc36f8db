"""The ``burley`` model (issue 34): its sample pattern and weights, and its gradients.
The twin, the engines' profiles and ``invsss fit`` are tested in the folders of their
layers (test_burley.py in each)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.burley_screen_space import burley_cdf, render_burley, unit_radii
from invsss.validation import InvalidInputError
from tests.forward._burley_scenes import D, burley_params, compiled_scene, small_scene


# ------------------------------------------------------------------ pattern and weights


def test_unit_radii_invert_the_cdf_where_bisection_does():
    n = 16
    x = unit_radii(n)
    targets = (np.arange(n) + 0.5) / n
    lo, hi = np.zeros(n), np.full(n, 100.0)
    for _ in range(200):  # bisection: an independent inverse of the increasing CDF
        mid = 0.5 * (lo + hi)
        below = burley_cdf(mid) < targets
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    np.testing.assert_allclose(x, 0.5 * (lo + hi), rtol=1e-10)


def test_each_channel_blurs_with_its_own_profile():
    """A radial kernel multiplies ``cos(k x)`` by its Hankel transform; for Burley's
    profile ``H(k) = (1 / sqrt(1 + k^2 d^2) + 3 / sqrt(1 + 9 k^2 d^2)) / 4``. At the pixel
    where ``I = cos(k (x - x0)) + cos(k (y - y0))`` peaks, the blur returns ``2 H_c(k)``.
    Only the widest channel is importance sampled; the others must get their own
    profile through their weights (with the widest one's, blue would give 1.42, not 1.85)."""
    size, centre, k = 101, 50, 0.2
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    image = (np.cos(k * (xx - centre)) + np.cos(k * (yy - centre)))[..., None].repeat(3, axis=-1)
    d = np.array([2.0, 1.0, 0.6])  # mm, and px: sss_level / depth = 1 px per mm
    with jax.enable_x64(True):
        out = render_burley(jnp.asarray(image), jnp.full((size, size), 500.0), jnp.ones((size, size)),
                            burley_params(d, level=500.0), samples=512)
    hankel = (1.0 / np.sqrt(1.0 + (k * d) ** 2) + 3.0 / np.sqrt(1.0 + 9.0 * (k * d) ** 2)) / 4.0
    np.testing.assert_allclose(np.asarray(out)[centre, centre], 2.0 * hankel, rtol=0.01)


def test_a_constant_stays_and_bad_distances_are_refused():
    image, depth, mask, _ = small_scene()
    flat = np.full_like(image, 0.7)
    out = invsss.render(flat, depth, mask, burley_params(), model="burley")
    np.testing.assert_allclose(np.asarray(out), 0.7, rtol=1e-6)
    with pytest.raises(InvalidInputError, match=r"^params.variances: the burley model takes d\^2 for one channel"):
        invsss.render(image, depth, mask, invsss.SSSParams(800.0, 0.0, 1.0, [1.0, 1.0], [1.0, 0.5]),
                      model="burley")


# ------------------------------------------------------------------ gradients


@pytest.fixture(scope="module")
def compiled():
    """The scene, functional and gradients of :func:`compiled_scene`, compiled once for
    this module."""
    return compiled_scene()


def test_gradients_match_finite_differences(compiled):
    image = compiled["scene"][0]
    g_d, g_level, _ = compiled["grads"]
    with jax.enable_x64(True):
        def at(d, level):
            return float(compiled["value"](jnp.asarray(d), jnp.asarray(level), jnp.asarray(image))[0])

        for c in range(3):
            step = np.zeros(3)
            step[c] = 1e-6
            fd = (at(D + step, 800.0) - at(D - step, 800.0)) / 2e-6
            assert float(g_d[c]) == pytest.approx(fd, rel=1e-5), c
        fd = (at(D, 800.0 + 1e-3) - at(D, 800.0 - 1e-3)) / 2e-3
    assert float(g_level) == pytest.approx(fd, rel=1e-5)
    assert np.all(g_d != 0) and float(g_level) != 0
