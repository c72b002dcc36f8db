"""The ``burley`` model's PyTorch twin against the JAX model: values and the gradients
in d, the level and the image."""

from __future__ import annotations

import numpy as np
import pytest

from tests.forward._burley_scenes import D, compiled_scene


@pytest.fixture(scope="module")
def compiled():
    """The JAX side: the scene, functional and gradients of :func:`compiled_scene`."""
    return compiled_scene()


def test_torch_twin_agrees_with_jax(compiled):
    torch = pytest.importorskip("torch")
    pytest.importorskip("kornia")
    import invsss.torch as itorch

    image, depth, mask, probe = compiled["scene"]
    out_j, (g_d_j, g_level_j, g_image_j) = compiled["out"], compiled["grads"]
    d = torch.tensor(D, requires_grad=True)
    level = torch.tensor(800.0, dtype=torch.float64, requires_grad=True)
    timage = torch.tensor(image, requires_grad=True)
    params = itorch.SSSParams(level, 0.0, 1.0, torch.ones(3, dtype=torch.float64), d**2)
    out_t = itorch.render(timage, torch.tensor(depth), torch.tensor(mask), params, "burley")
    (torch.tensor(probe) * out_t).sum().backward()
    assert np.max(np.abs(out_j - image)) > 1e-2  # it blurs: agreement is not vacuous
    # The issue asks for 1e-5 (values) and 1e-4 (gradients); in float64 the twins
    # agree to rounding, so the suite's cross-check tolerance (1e-6) applies.
    np.testing.assert_allclose(out_t.detach().numpy(), out_j, rtol=0, atol=1e-6 * np.abs(out_j).max())
    np.testing.assert_allclose(d.grad.numpy(), g_d_j, rtol=1e-6)
    assert float(level.grad) == pytest.approx(float(g_level_j), rel=1e-6)
    np.testing.assert_allclose(timage.grad.numpy(), g_image_j, rtol=0, atol=1e-6 * np.abs(g_image_j).max())
