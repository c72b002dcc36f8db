"""The Pallas pass kernel against the XLA reference pass (invsss.forward.pass_kernels).

On the CPU the kernels run in Pallas's interpreter (``interpret=True``), so CI
checks the kernel code itself: values, forward-mode (the estimator's
``jacfwd``) and reverse-mode derivatives against the reference and against
finite differences, on an image whose size is not a multiple of the tile.
Tests marked ``gpu`` run the compiled Triton kernels and need a GPU
(``pytest -m gpu`` on a machine with one; skipped elsewhere).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.pass_kernels import PASS_KERNEL_VARIABLE, directional_pass_kernel, kernel_enabled
from invsss.forward.passes import directional_pass_xla, tap_weights
from invsss.forward.screen_space import render_sog
from invsss.validation import InvalidInputError

#: A tile that leaves partial tiles on the 11 x 19 test image.
BLOCK = (4, 8)


def _inputs(h=11, w=19, seed=0):
    rng = np.random.default_rng(seed)
    image = jnp.asarray(rng.random((h, w, 3)), jnp.float32)
    # Footprints up to 4 px: taps reach past the border (clamp-to-edge).
    footprint = jnp.asarray(1.0 + 3.0 * rng.random((h, w)), jnp.float32)
    mask = jnp.asarray(rng.random((h, w)), jnp.float32)
    return image, footprint, mask, rng


def _fns(mask, axis, interpret=True, block=BLOCK):
    weights = tap_weights()

    def kernel(image, footprint):
        return directional_pass_kernel(image, footprint, mask, weights, axis, interpret=interpret, block=block)

    def reference(image, footprint):
        return directional_pass_xla(image, footprint, mask, weights, axis)

    return kernel, reference


@pytest.mark.slow
@pytest.mark.parametrize("axis", [1, 0])
def test_kernel_matches_reference_values_and_derivatives(axis):
    image, footprint, mask, rng = _inputs()
    kernel, reference = _fns(mask, axis)
    np.testing.assert_allclose(kernel(image, footprint), reference(image, footprint), atol=1e-6)
    d_image = jnp.asarray(rng.standard_normal(image.shape), jnp.float32)
    d_footprint = jnp.asarray(rng.standard_normal(footprint.shape), jnp.float32)
    tangents = (d_image, d_footprint)
    np.testing.assert_allclose(
        jax.jvp(kernel, (image, footprint), tangents)[1],
        jax.jvp(reference, (image, footprint), tangents)[1],
        atol=2e-6,
    )
    cotangent = jnp.asarray(rng.standard_normal(image.shape), jnp.float32)
    got = jax.vjp(kernel, image, footprint)[1](cotangent)
    want = jax.vjp(reference, image, footprint)[1](cotangent)
    np.testing.assert_allclose(got[0], want[0], atol=5e-6)
    np.testing.assert_allclose(got[1], want[1], atol=5e-6)


@pytest.mark.slow
def test_kernel_gradient_matches_finite_differences():
    image, _, mask, rng = _inputs(seed=1)
    # Interpolation is piecewise linear: footprints near 1.2 px keep every tap
    # (t f = 0.4, 0.8, 1.2 px) at least 0.15 px from a pixel centre, so the
    # finite differences below cross no kink.
    footprint = jnp.asarray(1.2 + 0.05 * rng.random(mask.shape), jnp.float32)
    kernel, _ = _fns(mask, 1)
    probe = jnp.asarray(rng.standard_normal(image.shape), jnp.float32)

    def loss(scale):
        # Widen every footprint and brighten the image by one scalar.
        return jnp.sum(probe * kernel(image * (1.0 + 0.5 * scale), footprint * (1.0 + scale)))

    step = 1e-2
    loss_at = jax.jit(loss)
    finite = (loss_at(step) - loss_at(-step)) / (2 * step)
    np.testing.assert_allclose(jax.grad(loss)(0.0), finite, rtol=2e-3)
    np.testing.assert_allclose(jax.jacfwd(loss)(0.0), finite, rtol=2e-3)


@pytest.mark.slow
def test_mask_and_tap_weight_gradients_match_reference():
    image, footprint, mask, rng = _inputs(seed=2)
    cotangent = jnp.asarray(rng.standard_normal(image.shape), jnp.float32)
    weights = tap_weights()

    def loss(fn, m, w):
        return jnp.sum(cotangent * fn(image, footprint, m, w, 0))

    kernel = lambda *a: directional_pass_kernel(*a, interpret=True, block=BLOCK)  # noqa: E731
    got = jax.grad(loss, argnums=(1, 2))(kernel, mask, weights)
    want = jax.grad(loss, argnums=(1, 2))(directional_pass_xla, mask, weights)
    np.testing.assert_allclose(got[0], want[0], atol=5e-6)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-5)


@pytest.mark.slow
def test_sog_model_through_the_kernel_matches_reference(monkeypatch):
    # The whole sog renderer (a scan over ten passes with rematerialisation)
    # with the kernel in the interpreter, against the XLA passes: value, the
    # gradient (reverse mode) and the Jacobian (forward mode, as the estimator).
    image, _, mask, rng = _inputs(h=12, w=10, seed=3)
    depth = jnp.asarray(450.0 + 50.0 * rng.random((12, 10)), jnp.float32)
    params = invsss.SSSParams(900.0, 30.0, 1.0, [0.3, 0.5, 0.2], [0.5, 2.0, 6.0])
    target = image * 0.9

    def loss(p):
        return jnp.mean((render_sog(image, depth, mask, p) - target) ** 2)

    def jacobian(scale):
        return render_sog(image, depth, mask, eqx.tree_at(lambda p: p.sss_level, params, params.sss_level * scale))

    results = {}
    for choice in ("xla", "interpret"):
        monkeypatch.setenv(PASS_KERNEL_VARIABLE, choice)
        assert kernel_enabled(image) == (choice == "interpret")
        value, grads = jax.value_and_grad(loss)(params)
        results[choice] = (value, grads, jax.jacfwd(jacobian)(1.0))
    (v0, g0, j0), (v1, g1, j1) = results["xla"], results["interpret"]
    np.testing.assert_allclose(v1, v0, rtol=1e-5)
    for name in ("sss_level", "correction", "maxdd", "weights", "variances"):
        np.testing.assert_allclose(getattr(g1, name), getattr(g0, name), rtol=2e-4, atol=1e-9, err_msg=name)
    np.testing.assert_allclose(j1, j0, atol=2e-5)


def test_unknown_kernel_choice_is_a_clear_error(monkeypatch):
    monkeypatch.setenv(PASS_KERNEL_VARIABLE, "cuda")
    with pytest.raises(InvalidInputError, match="INVSSS_PASS_KERNEL: expected one of"):
        kernel_enabled(jnp.zeros((4, 4, 3)))


# ------------------------------------------------------------ on a GPU


def _has_gpu() -> bool:
    try:
        return bool(jax.devices("gpu"))
    except RuntimeError:
        return False


@pytest.mark.gpu
@pytest.mark.skipif(not _has_gpu(), reason="needs a GPU")
@pytest.mark.parametrize("axis", [1, 0])
@pytest.mark.parametrize("x64", [False, True], ids=["float32", "float64"])
def test_triton_kernel_matches_reference_on_gpu(axis, x64):
    # The compiled kernels (Triton's gathers, which the interpreter does not
    # run) on a 257 x 300 image: partial tiles both ways; float64 is what the
    # estimator fits in. Reverse mode runs XLA's transpose on CUDA
    # (KERNEL_ON_CUDA); the value and the JVP are the Triton kernels'.
    with jax.enable_x64(x64):
        _check_on_gpu(axis, jnp.float64 if x64 else jnp.float32)


def _check_on_gpu(axis, dtype):
    image, footprint, mask, rng = _inputs(h=257, w=300, seed=4)
    image, footprint, mask = (x.astype(dtype) for x in (image, footprint * 3.0, mask))
    kernel, reference = _fns(mask, axis, interpret=False, block=None)
    kernel, reference = jax.jit(kernel), jax.jit(reference)
    np.testing.assert_allclose(kernel(image, footprint), reference(image, footprint), atol=1e-5)
    tangents = tuple(jnp.asarray(rng.standard_normal(x.shape), dtype) for x in (image, footprint))
    np.testing.assert_allclose(
        jax.jit(lambda i, f: jax.jvp(kernel, (i, f), tangents)[1])(image, footprint),
        jax.jit(lambda i, f: jax.jvp(reference, (i, f), tangents)[1])(image, footprint),
        atol=1e-4,
    )
    cotangent = jnp.asarray(rng.standard_normal(image.shape), dtype)
    got = jax.jit(lambda i, f: jax.vjp(kernel, i, f)[1](cotangent))(image, footprint)
    want = jax.jit(lambda i, f: jax.vjp(reference, i, f)[1](cotangent))(image, footprint)
    np.testing.assert_allclose(got[0], want[0], atol=1e-4)
    np.testing.assert_allclose(got[1], want[1], atol=1e-3, rtol=1e-4)


@pytest.mark.gpu
@pytest.mark.skipif(not _has_gpu(), reason="needs a GPU")
def test_kernel_is_the_gpu_default():
    image = jnp.zeros((8, 8, 3), jnp.float32)
    assert jax.default_backend() == "gpu"
    assert kernel_enabled(image) == (
        __import__("os").environ.get(PASS_KERNEL_VARIABLE, "auto") in ("auto", "pallas")
    )
