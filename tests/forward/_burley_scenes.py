"""Scenes for the ``burley`` model's tests: its parameters at Burley's d per channel, a
small random scene, and the model's functional and gradient compiled on it."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import invsss

D = np.array([1.1, 0.55, 0.3])  # Burley's d per channel, mm: red scatters furthest, as in skin


def burley_params(d=D, level=800.0):
    d = d if isinstance(d, jax.Array) else np.asarray(d, np.float64)  # traced under jax.grad
    return invsss.SSSParams(level, 0.0, 1.0, np.ones(d.shape[0]), d**2)


def small_scene(seed=0, h=20, w=24):
    """Random image, rippled depth (mm) and a fractional mask with zeros."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 500.0 + 6.0 * np.sin(0.4 * xx + 0.2 * yy) + 0.8 * xx
    mask = np.clip(0.5 + 0.9 * np.sin(0.35 * xx + 1.0) * np.cos(0.3 * yy), 0.0, 1.0)
    image = rng.uniform(0.05, 1.0, (h, w, 3))
    probe = rng.normal(size=(h, w, 3))
    return image, depth, mask, probe


def burley_functional(image, depth, mask, probe):
    """``(d, level, image) -> (sum(probe * render), render)``, compiled once (float64)."""
    def functional(d, level, image):
        out = invsss.render(image, depth, mask, burley_params(d, level), model="burley")
        return jnp.sum(jnp.asarray(probe) * out), out

    return jax.jit(functional), jax.jit(jax.grad(functional, argnums=(0, 1, 2), has_aux=True))


def compiled_scene():
    """One scene, its compiled functional and gradient, and the JAX gradients at ``D``
    (for a module-scoped fixture shared by the finite-difference check, or the twin's)."""
    image, depth, mask, probe = small_scene(1)
    with jax.enable_x64(True):
        value, grad = burley_functional(image, depth, mask, probe)
        grads, out = grad(jnp.asarray(D), jnp.asarray(800.0), jnp.asarray(image))
    return {"scene": (image, depth, mask, probe), "value": value, "out": np.asarray(out),
            "grads": [np.asarray(g) for g in grads]}
