"""Lit scenes for the light-term tests (docs/model.md, section 8).

Model-made pairs with their light buffers (:func:`dome_with_two_lights`, a textured
dome under a key and a fill light, with the key light's part of the source;
:func:`lit_card`, a card turning away from the camera), and small random scenes with
a NumPy reference of the law (:func:`light_terms_scene`, :func:`law_scene`,
:func:`fill_scene`, :func:`law_reference`)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

import invsss
from invsss.forward.light_terms import LightBuffers


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def dome_with_two_lights(size=40, seed=2):
    """A textured dome lit by a key light from the upper left and a weaker fill
    from the right, RGB: the source, the key light's part, and the buffers (the
    fill's direction too)."""
    rng = np.random.default_rng(seed)
    texture = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, (size, size)), 1.5) * 2.0 + 0.3
    texture[:, 14:17] *= 0.3
    albedo = np.stack([texture, 0.8 * texture, 0.6 * texture], axis=-1) / 3.0
    y, x = (np.mgrid[0:size, 0:size] - (size - 1) / 2.0) / (size / 2.0)
    r2 = np.minimum(x**2 + y**2, 0.9)
    normal = unit(np.stack([0.9 * x, -0.9 * y, np.sqrt(1.0 - 0.81 * r2)], axis=-1))
    depth = 500.0 - 40.0 * np.sqrt(1.0 - 0.81 * r2)
    to_key = unit(np.array([-0.6, 0.3, 0.74]))
    to_fill = unit(np.array([0.5, 0.2, 0.84]))
    key = albedo * 0.9 * np.clip(normal @ to_key, 0.0, 1.0)[..., None]
    source = key + albedo * 0.4 * np.clip(normal @ to_fill, 0.0, 1.0)[..., None]
    light = np.broadcast_to(to_key, normal.shape).copy()
    fill_light = np.broadcast_to(to_fill, normal.shape).copy()
    mask = (x**2 + y**2 < 0.85).astype(float)
    return source, depth, mask, LightBuffers(normal=normal, light=light, key=key, fill_light=fill_light)


PROFILE = {"weights": [0.5, 0.5], "variances": [0.5, 2.0]}
FIX = {"correction": 0.0, "maxdd": 1.0}
TRUTH = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])


def lit_target(source, depth, mask, buffers, terms, noise=0.002):
    target = np.asarray(invsss.render(source, depth, mask, TRUTH, light_terms=terms, light_buffers=buffers))
    return target + np.random.default_rng(1).normal(0.0, noise, target.shape)


#: The size of the random scenes.
H, W = 12, 15
#: The parameters of the law's tests.
LAW_PARAMS = invsss.SSSParams(800.0, 300.0, 0.5, [0.5, 0.5], [0.3, 1.5])


def light_terms_scene(seed=0):
    """A random H x W image, depth, mask with a soft edge, unit light directions and normals,
    and the parameters of the light terms' tests."""
    rng = np.random.default_rng(seed)
    image = rng.uniform(0.2, 1.0, (H, W, 3))
    depth = 500.0 + rng.uniform(0.0, 20.0, (H, W))
    mask = np.ones((H, W))
    mask[:2] = 0.0
    mask[2, :4] = 0.5
    light = rng.normal(size=(H, W, 3))
    light[..., 2] = np.abs(light[..., 2]) + 1.0
    normal = rng.normal(size=(H, W, 3))
    normal[..., 2] = np.abs(normal[..., 2]) + 0.3
    params = invsss.SSSParams(800.0, 300.0, 0.5, [0.5, 0.5], [0.3, 1.5])
    return image, depth, mask, unit(light), unit(normal), params


def law_scene(seed=0):
    """Random source and key light's part, normals and light directions, some of
    them facing away from the light (``n . l < 0``: the key light does not reach)."""
    rng = np.random.default_rng(seed)
    key = rng.uniform(0.0, 0.6, (H, W, 3))
    source = key + rng.uniform(0.1, 0.4, (H, W, 3))
    depth = 500.0 + rng.uniform(0.0, 20.0, (H, W))
    mask = np.ones((H, W))
    mask[:2] = 0.0
    mask[2, :4] = 0.5
    normal = rng.normal(size=(H, W, 3))
    normal[..., 2] = np.abs(normal[..., 2]) + 0.3
    light = rng.normal(size=(H, W, 3))
    light[..., 2] = np.abs(light[..., 2]) + 0.2
    return source, key, depth, mask, unit(normal), unit(light)


def fill_scene(seed=0):
    """:func:`law_scene` and a unit direction to the other lights."""
    source, key, depth, mask, normal, light = law_scene(seed)
    rng = np.random.default_rng(seed + 100)
    fill_light = rng.normal(size=light.shape)
    fill_light[..., 2] = np.abs(fill_light[..., 2]) + 0.2
    return source, key, depth, mask, normal, light, unit(fill_light)


def law_reference(source, key, mask, normal, light, albedo, strength=1.0):
    """docs/model.md, section 8, written out: S + m a K (g - 1), with
    g = 1 + t (f_w(mu, mu0) / f_w(1, 1) - 1) and t = clip(min(n_z, n . l) / 0.1, 0, 1)."""
    w = np.broadcast_to(np.asarray(albedo, np.float64), (source.shape[-1],))
    out = np.empty_like(source)
    n_dot_l = np.einsum("hwk,hwk->hw", normal, light)
    trust = np.clip(np.minimum(normal[..., 2], n_dot_l) / 0.1, 0.0, 1.0)
    for c in range(source.shape[-1]):
        root = np.sqrt(1.0 - w[c])

        def h(x):
            return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * root)

        mu = np.clip(normal[..., 2], 0.0, 1.0)
        mu0 = np.clip(n_dot_l, 0.0, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            law = np.where(trust > 0, h(mu) * h(mu0) / (mu + mu0), 0.0)
        head_on = h(1.0) * h(1.0) / 2.0
        gain = 1.0 + trust * (law / head_on - 1.0)
        out[..., c] = source[..., c] + strength * mask * key[..., c] * (gain - 1.0)
    return out


def lit_card(size=48):
    """A model-made pair with both terms: a textured card turning away from the
    camera (normals from -45 to 45 degrees), lit from the upper left, with dark
    vertical stripes so that the shift moves edges."""
    rng = np.random.default_rng(0)
    source = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, (size, size)), 1.5) * 2.0 + 0.3
    source[:, 18:22] *= 0.3
    source[:, 32:34] *= 0.4
    depth = np.full((size, size), 500.0) + np.linspace(0.0, 30.0, size)[None]
    light = np.zeros((size, size, 3))
    light[..., 0], light[..., 1] = -0.5, 0.3
    light[..., 2] = np.sqrt(1.0 - 0.34)
    normal = np.zeros((size, size, 3))
    normal[..., 0] = np.linspace(-0.7, 0.7, size)[None]
    normal[..., 2] = np.sqrt(1.0 - normal[..., 0] ** 2)
    mask = np.zeros((size, size))
    mask[2:-2, 2:-2] = 1.0
    return source, depth, mask, LightBuffers(normal=normal, light=light)
