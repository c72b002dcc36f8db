"""The JAX forward model against docs/model.md and independent plain-NumPy references.

The references below are written from the text of docs/model.md and the thesis's
Listing 4.1 with explicit loops, not from the JAX code, so an error in the
vectorised implementation (an index, an edge rule, a sort) shows up as a
mismatch. Comparisons that should agree to rounding run in float64 under
``jax.enable_x64(True)``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import invsss
from invsss import (
    InvalidInputError,
    SSSParams,
    render,
    render_sog,
    separable_kernel,
    stretch_factors,
)
from invsss.forward.passes import directional_pass

# Published 7-tap weight sets, typed in again from docs/model.md, section 3.
JIMENEZ_TAPS = np.array([0.006, 0.061, 0.242, 0.382, 0.242, 0.061, 0.006])
THESIS_TAPS = np.array([0.1053, 0.1402, 0.1664, 0.1762, 0.1664, 0.1402, 0.1053])


@pytest.fixture
def x64():
    with jax.enable_x64(True):
        yield


# ---------------------------------------------------------------- scenes


# Most tests share one image size and number of Gaussians so that the jitted
# renderer is compiled once per model and dtype, not once per test.
H, W, K = 8, 9, 3


def make_scene(h=H, w=W, channels=3, seed=0, binary_mask=False):
    """A small curved surface (depth ~ 60 with slopes up to ~6 per pixel), a random
    image and a mask with a hole, a zero border and (optionally) fractional values."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 60.0 + 12.0 * np.sin(x / 2.1 + 0.3) * np.cos(y / 2.7 - 0.2) + 0.3 * rng.standard_normal((h, w))
    image = rng.uniform(0.05, 1.0, (h, w, channels))
    mask = np.ones((h, w))
    mask[:, 0] = 0.0
    mask[-1, :] = 0.0
    mask[h // 2, w // 2] = 0.0
    if not binary_mask:
        mask[1, 1:4] = [0.25, 0.5, 0.8]
        mask[2:4, -1] = 0.6
    return image, depth, mask


def scene_params(k=K, channels=3, seed=1):
    """Generic parameters: footprints of 1-6 pixels on :func:`make_scene`, some slopes
    above ``maxdd`` and some below, distinct variances, no weight at 0."""
    rng = np.random.default_rng(seed)
    variances = np.sort(rng.uniform(0.3, 4.0, k))[rng.permutation(k)]  # unsorted on purpose
    shape = (k,) if channels is None else (k, channels)
    weights = rng.uniform(0.2, 1.0, shape)
    return SSSParams(61.3, 2.7, 2.3, weights, variances)


# ---------------------------------------------------------------- NumPy references


def np_slopes(depth):
    """``(|dd/dx|, |dd/dy|)``: central differences inside, one-sided on the border
    (numpy.gradient's stencil), written as explicit loops."""
    h, w = depth.shape
    ddx = np.empty_like(depth)
    ddy = np.empty_like(depth)
    for y in range(h):
        for x in range(w):
            if x == 0:
                ddx[y, x] = depth[y, 1] - depth[y, 0]
            elif x == w - 1:
                ddx[y, x] = depth[y, w - 1] - depth[y, w - 2]
            else:
                ddx[y, x] = (depth[y, x + 1] - depth[y, x - 1]) / 2.0
            if y == 0:
                ddy[y, x] = depth[1, x] - depth[0, x]
            elif y == h - 1:
                ddy[y, x] = depth[h - 1, x] - depth[h - 2, x]
            else:
                ddy[y, x] = (depth[y + 1, x] - depth[y - 1, x]) / 2.0
    return np.abs(ddx), np.abs(ddy)


def np_stretch(depth, sss_level, correction, maxdd):
    slope_x, slope_y = np_slopes(depth)
    s_x = sss_level / (depth + correction * np.minimum(slope_x, maxdd))
    s_y = sss_level / (depth + correction * np.minimum(slope_y, maxdd))
    return s_x, s_y


def np_sample(line, u):
    """``line`` (n, C) read at real coordinate ``u``: clamp-to-edge, then linear
    interpolation between the two nearest pixel centres."""
    n = line.shape[0]
    u = min(max(u, 0.0), n - 1.0)
    i0 = int(np.floor(u))
    i1 = min(i0 + 1, n - 1)
    a = u - i0
    return (1.0 - a) * line[i0] + a * line[i1]


def np_directional_pass(image, footprint, mask, taps, axis):
    """docs/model.md, section 3: ``sum_k W_k I(x + (k/3) f)``, blended ``m P + (1 - m) I``."""
    h, w, _ = image.shape
    out = np.empty_like(image)
    for y in range(h):
        for x in range(w):
            line, centre = (image[y, :, :], x) if axis == 1 else (image[:, x, :], y)
            acc = np.zeros(image.shape[2])
            for k in range(-3, 4):
                acc += taps[k + 3] * np_sample(line, centre + (k / 3.0) * footprint[y, x])
            out[y, x] = mask[y, x] * acc + (1.0 - mask[y, x]) * image[y, x]
    return out


def np_spread(taps):
    return np.sqrt(sum(taps[k + 3] * (k / 3.0) ** 2 for k in range(-3, 4)))


def np_render_sog(image, depth, mask, sss_level, correction, maxdd, weights, variances, taps=JIMENEZ_TAPS):
    """docs/model.md, section 5, ``sog``, straight from the text."""
    s_x, s_y = np_stretch(depth, sss_level, correction, maxdd)
    c_w = np_spread(taps)
    order = np.argsort(variances, kind="stable")
    weights = np.asarray(weights, np.float64)
    weights = weights.reshape(len(variances), -1)[order]  # (K, 1 or C)
    layer, previous, acc = image, 0.0, 0.0
    for i, v in zip(range(len(order)), np.asarray(variances)[order]):
        width = np.sqrt(v - previous) / c_w
        layer = np_directional_pass(layer, s_x * width, mask, taps, axis=1)
        layer = np_directional_pass(layer, s_y * width, mask, taps, axis=0)
        acc = acc + weights[i] * layer
        previous = v
    return acc / weights.sum(axis=0)


def np_listing_4_1_pass(main_tex, depth, mesh_mask, sss_level, correction, maxdd, axis):
    """One pass of the thesis's Listing 4.1, in pixel units.

    The shader's ``kernel_width = 7 / _ScreenParams.x`` is 7 pixels in texture
    coordinates; its bilinear clamp-to-edge sampler at texture coordinate
    ``(x + 0.5) / W`` reads pixel centre ``x``, so pixel coordinates with
    clamping to ``[0, n - 1]`` and linear interpolation are the same lookup.
    ``ddx``/``ddy`` of the depth are numpy.gradient's stencil (docs/model.md, section 2).
    """
    w = [0.1053, 0.1402, 0.1664, 0.1762, 0.1664, 0.1402, 0.1053]
    kernel_width = 7.0
    slope_x, slope_y = np_slopes(depth)
    slope = slope_x if axis == 1 else slope_y
    h, wd, _ = main_tex.shape
    out = np.empty_like(main_tex)
    for y in range(h):
        for x in range(wd):
            if mesh_mask[y, x] == 0.0:
                out[y, x] = main_tex[y, x]
                continue
            s = sss_level / (depth[y, x] + correction * min(abs(slope[y, x]), maxdd))
            final_width = s * kernel_width
            line, centre = (main_tex[y], x) if axis == 1 else (main_tex[:, x], y)
            offset = centre - final_width
            colour = np.zeros(main_tex.shape[2])
            for i in range(7):
                colour += np_sample(line, offset) * w[i]
                offset += final_width / 3.0
            out[y, x] = colour
    return out


def np_separable_kernel(weights, variances, taps, strength):
    """Jimenez et al. 2015's kernel as docs/model.md, section 5 describes it, with loops."""
    radius = 3.0 if taps > 20 else 2.0
    step = 2.0 * radius / (taps - 1)
    offsets = []
    for i in range(taps):
        u = -radius + i * step
        offsets.append(radius * np.sign(u) * u**2 / radius**2)
    weights = np.asarray(weights, np.float64).reshape(len(variances), -1)
    kernel = np.zeros((taps, weights.shape[1]))
    for i in range(taps):
        left = abs(offsets[i] - offsets[i - 1]) if i > 0 else 0.0
        right = abs(offsets[i] - offsets[i + 1]) if i < taps - 1 else 0.0
        interval = (left + right) / 2.0
        r = abs(offsets[i])
        for g, v in enumerate(variances):
            kernel[i] += interval * weights[g] * np.exp(-(r**2) / (2 * v)) / (2 * np.pi * v)
    kernel /= kernel.sum(axis=0)
    kernel *= strength
    kernel[taps // 2] += 1.0 - strength
    return np.array(offsets), kernel


def np_separable_pass(image, scale, mask, offsets, kernel, axis):
    h, w, _ = image.shape
    out = np.empty_like(image)
    for y in range(h):
        for x in range(w):
            line, centre = (image[y], x) if axis == 1 else (image[:, x], y)
            acc = np.zeros(image.shape[2])
            for o, kw in zip(offsets, kernel):
                acc += kw * np_sample(line, centre + o * scale[y, x])
            out[y, x] = mask[y, x] * acc + (1.0 - mask[y, x]) * image[y, x]
    return out


# ---------------------------------------------------------------- references vs JAX


def test_stretch_factors_match_formula(x64):
    _, depth, _ = make_scene(h=7, w=10)
    for correction, maxdd in [(0.0, 1.0), (2.7, 2.3), (5.0, 100.0)]:
        s_x, s_y = stretch_factors(jnp.asarray(depth), 61.3, correction, maxdd)
        r_x, r_y = np_stretch(depth, 61.3, correction, maxdd)
        np.testing.assert_allclose(np.asarray(s_x), r_x, rtol=1e-13)
        np.testing.assert_allclose(np.asarray(s_y), r_y, rtol=1e-13)
    # The scene really has slopes on both sides of maxdd = 2.3, so min() is exercised.
    slope_x, slope_y = np_slopes(depth)
    assert (slope_x > 2.3).any() and (slope_x < 2.3).any() and (slope_y > 2.3).any()


@pytest.mark.slow
@pytest.mark.parametrize("axis", [0, 1])
@pytest.mark.parametrize("taps", [JIMENEZ_TAPS, THESIS_TAPS], ids=["jimenez", "thesis"])
def test_directional_pass_matches_loops(x64, axis, taps):
    image, _, mask = make_scene()
    rng = np.random.default_rng(3)
    # Footprints large enough that taps leave the image (clamp-to-edge) and fractional.
    footprint = rng.uniform(0.0, 9.0, image.shape[:2])
    got = directional_pass(jnp.asarray(image), jnp.asarray(footprint), jnp.asarray(mask), jnp.asarray(taps), axis)
    want = np_directional_pass(image, footprint, mask, taps, axis)
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12, atol=1e-14)


def test_fractional_mask_blends_pass_with_input(x64):
    image, _, _ = make_scene(h=6, w=7)
    rng = np.random.default_rng(4)
    footprint = jnp.asarray(rng.uniform(0.5, 4.0, image.shape[:2]))
    m = rng.uniform(0.0, 1.0, image.shape[:2])
    taps = jnp.asarray(JIMENEZ_TAPS)
    full = np.asarray(directional_pass(jnp.asarray(image), footprint, jnp.ones(m.shape), taps, 1))
    got = np.asarray(directional_pass(jnp.asarray(image), footprint, jnp.asarray(m), taps, 1))
    np.testing.assert_allclose(got, m[..., None] * full + (1 - m[..., None]) * image, rtol=1e-13)


def test_sog_matches_reference(x64):
    image, depth, mask = make_scene()
    p = scene_params()
    got = render(image, depth, mask, p, "sog")
    want = np_render_sog(image, depth, mask, 61.3, 2.7, 2.3, np.asarray(p.weights), np.asarray(p.variances))
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12, atol=1e-14)


def test_thesis_single_gaussian_is_listing_4_1(x64):
    # Listing 4.1's kernel width of 7 pixels is f = 7 s, i.e. v = (7 c_W)^2.
    image, depth, mask = make_scene(binary_mask=True)
    sss_level, correction, maxdd = 25.0, 3.1, 2.4
    variance = (7.0 * np_spread(THESIS_TAPS)) ** 2
    p = SSSParams(sss_level, correction, maxdd, [1.0], [variance])
    got = np.asarray(render(image, depth, mask, p, "thesis"))
    horizontal = np_listing_4_1_pass(image, depth, mask, sss_level, correction, maxdd, axis=1)
    want = np_listing_4_1_pass(horizontal, depth, mask, sss_level, correction, maxdd, axis=0)
    # The footprint is ~3 px: the taps straddle pixels and hit the clamped border.
    s_x, _ = np_stretch(depth, sss_level, correction, maxdd)
    assert 2.0 < (7 * s_x).min() and (7 * s_x).max() < 4.5
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-14)
    assert np.abs(got - image).max() > 0.05  # the reference is not trivially the input


def test_thesis_chains_all_horizontal_then_all_vertical(x64):
    image, depth, mask = make_scene()
    p = scene_params()
    v = np.asarray(p.variances)
    s_x, s_y = np_stretch(depth, 61.3, 2.7, 2.3)
    c_w = np_spread(THESIS_TAPS)
    out = image
    for axis, s in [(1, s_x), (0, s_y)]:
        for vi in v:  # in the given order, not sorted
            out = np_directional_pass(out, s * np.sqrt(vi) / c_w, mask, THESIS_TAPS, axis)
    got = render(image, depth, mask, p, "thesis")
    np.testing.assert_allclose(np.asarray(got), out, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("taps", [11, 17, 25])
@pytest.mark.parametrize("per_channel", [False, True])
def test_separable_kernel_matches_reference(x64, taps, per_channel):
    w = np.array([[0.233, 0.455, 0.649], [0.100, 0.336, 0.344], [0.118, 0.198, 0.0], [0.113, 0.007, 0.007]])
    v = np.array([0.0064, 0.0484, 0.187, 0.567])
    if not per_channel:
        w = w[:, 0]
    strength = 0.7
    offsets, kernel = separable_kernel(jnp.asarray(w), jnp.asarray(v), taps, strength)
    want_offsets, want_kernel = np_separable_kernel(w, v, taps, strength)
    np.testing.assert_allclose(np.asarray(offsets), want_offsets, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(np.asarray(kernel), want_kernel, rtol=1e-12, atol=1e-15)
    assert np.abs(want_offsets).max() == pytest.approx(3.0 if taps > 20 else 2.0)


def test_separable_matches_reference(x64):
    image, depth, mask = make_scene()
    p = SSSParams(150.0, 2.7, 2.3, [[0.2, 0.5, 0.9], [0.6, 0.4, 0.1]], [0.4, 2.5])
    offsets, kernel = np_separable_kernel(np.asarray(p.weights), np.asarray(p.variances), 11, 0.85)
    scale = 150.0 / depth  # no correction term in this model
    want = np_separable_pass(image, scale, mask, offsets, kernel, axis=1)
    want = np_separable_pass(want, scale, mask, offsets, kernel, axis=0)
    got = render(image, depth, mask, p, "separable", taps=11, strength=0.85)
    np.testing.assert_allclose(np.asarray(got), want, rtol=1e-12, atol=1e-14)


# ---------------------------------------------------------------- special cases


def test_constant_image_stays_constant_under_sog(x64):
    _, depth, mask = make_scene()
    assert np.abs(np.diff(depth, axis=1)).max() > 3.0  # non-trivial slopes
    image = np.full(depth.shape + (3,), 0.37)
    p = scene_params()
    out = np.asarray(render(image, depth, mask, p, "sog"))
    np.testing.assert_allclose(out, 0.37, rtol=1e-13)


@pytest.mark.parametrize("model", ["sog", "thesis", "separable"])
def test_outside_mask_is_bit_exact(model):
    image, depth, mask = make_scene()
    image = image.astype(np.float32)
    p = scene_params()
    out = np.asarray(render(image, depth, mask, p, model))
    assert out.dtype == np.float32
    outside = mask == 0
    assert outside.sum() > 10 and np.abs(out[~outside] - image[~outside]).max() > 1e-3
    np.testing.assert_array_equal(out[outside], image[outside])


@pytest.mark.parametrize("model", ["sog", "thesis"])
def test_zero_variance_is_identity(x64, model):
    image, depth, mask = make_scene()
    p = SSSParams(61.3, 2.7, 2.3, [1.0], [0.0])
    np.testing.assert_allclose(np.asarray(render(image, depth, mask, p, model)), image, rtol=1e-13)


def test_zero_variance_layer_is_the_input(x64):
    image, depth, mask = make_scene()
    with_zero = SSSParams(61.3, 2.7, 2.3, [0.3, 0.7], [1.9, 0.0])
    single = SSSParams(61.3, 2.7, 2.3, [1.0], [1.9])
    got = np.asarray(render(image, depth, mask, with_zero, "sog"))
    want = 0.3 * np.asarray(render(image, depth, mask, single, "sog")) + 0.7 * image
    np.testing.assert_allclose(got, want, rtol=1e-13)
    # In the thesis chain a zero-variance pass is simply skipped.
    got = render(image, depth, mask, with_zero, "thesis")
    np.testing.assert_allclose(np.asarray(got), np.asarray(render(image, depth, mask, single, "thesis")), rtol=1e-13)


def test_equal_variances_merge_into_one_layer(x64):
    image, depth, mask = make_scene()
    w = np.array([[0.2, 0.5, 0.1], [0.3, 0.1, 0.6], [0.4, 0.3, 0.2]])
    twice = SSSParams(61.3, 2.7, 2.3, w, [2.2, 0.8, 2.2])
    merged = SSSParams(61.3, 2.7, 2.3, [w[0] + w[2], w[1]], [2.2, 0.8])
    got = np.asarray(render(image, depth, mask, twice, "sog"))
    np.testing.assert_allclose(got, np.asarray(render(image, depth, mask, merged, "sog")), rtol=1e-13)


@pytest.mark.parametrize("model", invsss.MODELS)
def test_linear_in_image(x64, model):
    image, depth, mask = make_scene(seed=5)
    other, _, _ = make_scene(seed=6)
    p = scene_params()
    a, b = 0.7, -1.3
    kw = {"follow_surface": 0.05} if model == "separable" else {}
    lhs = render(a * image + b * other, depth, mask, p, model, **kw)
    rhs = a * np.asarray(render(image, depth, mask, p, model, **kw)) + b * np.asarray(
        render(other, depth, mask, p, model, **kw)
    )
    np.testing.assert_allclose(np.asarray(lhs), rhs, rtol=1e-12, atol=1e-13)


# ---------------------------------------------------------------- gradients


def _fd_gradient(f, theta, rel_step=1e-7):
    grad = np.zeros_like(theta)
    for j in range(theta.size):
        h = rel_step * max(abs(theta[j]), 1e-2)
        up, down = theta.copy(), theta.copy()
        up[j] += h
        down[j] -= h
        grad[j] = (float(f(up)) - float(f(down))) / (2 * h)
    return grad


@pytest.mark.slow
@pytest.mark.parametrize(
    "model,channels,kwargs",
    [
        ("sog", 3, {}),
        ("thesis", None, {}),
        ("separable", 3, {"taps": 11, "follow_surface": 0.03}),
    ],
    ids=["sog", "thesis", "separable"],
)
def test_gradients_match_finite_differences(x64, model, channels, kwargs):
    image, depth, mask = make_scene(h=12, w=13, seed=7)
    rng = np.random.default_rng(8)
    probe = rng.standard_normal(image.shape)  # a generic linear functional of the output
    p = scene_params(k=4, channels=channels, seed=9)
    theta0, unravel = ravel_pytree(p)
    theta1 = theta0 * (1.0 + 0.1 * jnp.asarray(rng.uniform(-1.0, 1.0, theta0.shape)))

    @jax.jit
    def loss(theta):
        out = render(image, depth, mask, unravel(theta), model, **kwargs)
        return jnp.sum(probe * out)

    if model == "sog":
        # jit(vmap(grad)) at two parameter points: the transformations compose, and
        # each row must be the gradient at its own point.
        points = (theta0, theta1)
        grads = np.asarray(jax.jit(jax.vmap(jax.grad(loss)))(jnp.stack(points)))
    else:
        points = (theta1,)
        grads = np.asarray(jax.grad(loss)(theta1))[None]
    for grad, theta in zip(grads, points):
        fd = _fd_gradient(loss, np.asarray(theta))
        scale = np.abs(fd).max()
        np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-6 * scale)
    # Every parameter that enters the model must have a visible effect in this scene.
    g = unravel(jnp.asarray(fd))
    live = {"sss_level", "weights", "variances"} | ({"correction", "maxdd"} if model != "separable" else set())
    if model == "thesis":
        live.discard("weights")
    for name in ("sss_level", "correction", "maxdd", "weights", "variances"):
        magnitude = float(jnp.abs(getattr(g, name)).min())
        if name in live:
            assert magnitude > 1e-4 * scale, name
        else:
            assert float(jnp.abs(getattr(g, name)).max()) == 0.0, name


# ---------------------------------------------------------------- transformations and dtypes


def test_vmap_over_images_equals_loop():
    image, depth, mask = make_scene()
    images = np.stack([image, image[::-1, ::-1] * 0.5, image**2]).astype(np.float32)
    p = scene_params()
    batched = jax.jit(jax.vmap(render_sog, in_axes=(0, None, None, None)))(images, depth, mask, p)
    for i in range(len(images)):
        np.testing.assert_allclose(
            np.asarray(batched[i]), np.asarray(render(images[i], depth, mask, p)), rtol=1e-6, atol=1e-7
        )


def test_render_entry_point_traces_over_the_image():
    image, depth, mask = make_scene()
    images = np.stack([image, 0.5 * image]).astype(np.float32)
    p = scene_params()
    batched = jax.vmap(lambda im: render(im, depth, mask, p))(images)
    np.testing.assert_allclose(np.asarray(batched[1]), 0.5 * np.asarray(batched[0]), rtol=1e-6)


def test_vmap_over_parameter_sets_equals_loop():
    image, depth, mask = make_scene()
    sets = [scene_params(seed=s) for s in (11, 12, 13)]
    stacked = jax.tree.map(lambda *leaves: jnp.stack(leaves), *sets)
    outs = jax.jit(jax.vmap(render_sog, in_axes=(None, None, None, 0)))(
        jnp.asarray(image, jnp.float32), depth, mask, stacked
    )
    for i, p in enumerate(sets):
        np.testing.assert_allclose(np.asarray(outs[i]), np.asarray(render(image, depth, mask, p)), rtol=1e-6, atol=1e-7)
    assert np.abs(np.asarray(outs[0] - outs[1])).max() > 1e-3


def test_float32_by_default_and_float64_under_x64():
    image, depth, mask = make_scene()  # float64 NumPy arrays
    p = scene_params()
    assert render(image, depth, mask, p).dtype == jnp.float32
    # eval_shape traces every model (checks included) without compiling it.
    for model in invsss.MODELS:
        assert jax.eval_shape(lambda: render(image, depth, mask, p, model)).dtype == jnp.float32
    with jax.enable_x64(True):
        p64 = scene_params()
        assert p64.variances.dtype == jnp.float64
        assert render(image, depth, mask, p64).dtype == jnp.float64
        for model in invsss.MODELS:
            assert jax.eval_shape(lambda: render(image, depth, mask, p64, model)).dtype == jnp.float64


# ---------------------------------------------------------------- channels and shapes


@pytest.mark.slow
@pytest.mark.parametrize("model", ["sog", "separable"])
def test_per_channel_weights_act_per_channel(x64, model):
    image, depth, mask = make_scene()
    p = scene_params()
    rgb = np.asarray(render(image, depth, mask, p, model))
    for c in range(3):
        single = SSSParams(p.sss_level, p.correction, p.maxdd, p.weights[:, c], p.variances)
        alone = np.asarray(render(image[..., c : c + 1], depth, mask, single, model))
        np.testing.assert_allclose(rgb[..., c : c + 1], alone, rtol=1e-12)
    # ... and channel 1 really differs from what channel 0's weights would give it.
    other = SSSParams(p.sss_level, p.correction, p.maxdd, p.weights[:, 0], p.variances)
    assert np.abs(np.asarray(render(image[..., 1:2], depth, mask, other, model)) - rgb[..., 1:2]).max() > 1e-4


@pytest.mark.slow
@pytest.mark.parametrize("model", invsss.MODELS)
def test_one_channel_and_2d_images(x64, model):
    image, depth, mask = make_scene(channels=1)
    p = scene_params(channels=None)
    if model == "burley":  # issue 34: burley reads the variances as d^2, one (or one per channel)
        p = SSSParams(p.sss_level, p.correction, p.maxdd, p.weights[:1], p.variances[:1])
    one = np.asarray(render(image, depth, mask, p, model))
    flat = np.asarray(render(image[..., 0], depth, mask, p, model))
    assert one.shape == image.shape and flat.shape == image.shape[:2]
    np.testing.assert_array_equal(flat, one[..., 0])
    if model == "thesis":
        return  # the weights do not enter the thesis chain
    # A (K, 1) weight column broadcasts over the channels like (K,) weights.
    rgb, _, _ = make_scene(channels=3)
    column = SSSParams(p.sss_level, p.correction, p.maxdd, p.weights[:, None], p.variances)
    np.testing.assert_allclose(
        np.asarray(render(rgb, depth, mask, column, model)), np.asarray(render(rgb, depth, mask, p, model)), rtol=1e-13
    )


# ---------------------------------------------------------------- validation


def _bad_inputs():
    image, depth, mask = make_scene()
    p = scene_params()
    nan_depth = depth.copy()
    nan_depth[2, 3] = np.nan
    zero_depth = depth.copy()
    zero_depth[0, 1] = 0.0  # a masked pixel: column 0 is off the mask
    rgb_weights = SSSParams(1.0, 0.0, 1.0, np.ones((2, 3)), [0.5, 1.0])
    return [
        ("image", (image[..., :2], depth, mask, p), {}),
        ("image", (image[None], depth, mask, p), {}),
        ("image", (image[:1], depth[:1], mask[:1], p), {}),
        ("image", ((image * 255).astype(np.uint8), depth, mask, p), {}),
        ("depth", (image, depth[:, :-1], mask, p), {}),
        ("depth", (image, nan_depth, mask, p), {}),
        ("depth", (image, zero_depth, mask, p), {}),
        ("depth", (image, -depth, mask, p), {}),
        ("mask", (image, depth, mask[:-1], p), {}),
        ("mask", (image, depth, np.zeros_like(mask), p), {}),
        ("mask", (image, depth, mask * 2.0, p), {}),
        ("model", (image, depth, mask, p), {"model": "sum_of_gaussians"}),
        ("weights", (image[..., :1], depth, mask, rgb_weights), {}),
        ("params", (image, depth, mask, {"sss_level": 1.0}), {}),
        ("tap_weights", (image, depth, mask, p), {"tap_weights": "gauss"}),
        ("weights", (image, depth, mask, SSSParams(800.0, 0.0, 1.0, [0.3, 0.3, 0.4], [0.5, 1.0])), {}),
        ("sss_level", (image, depth, mask, SSSParams([800.0, 1.0], 0.0, 1.0, [0.5, 0.5], [0.5, 1.0])), {}),
        ("variances", (image, depth, mask, SSSParams(800.0, 0.0, 1.0, [0.5, 0.5], [[0.5, 1.0]])), {}),
    ]


@pytest.mark.parametrize("name,args,kwargs", _bad_inputs(), ids=lambda v: v if isinstance(v, str) else "")
def test_invalid_input_raises_one_line_error(name, args, kwargs):
    with pytest.raises(InvalidInputError) as info:
        render(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    assert name in message
