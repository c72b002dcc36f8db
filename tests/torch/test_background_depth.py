"""Renderer-style depth (0 or +inf off the mask) in the PyTorch twin: accepted, and the
same image as the JAX model gives."""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from tests.forward._background_scene import PARAMS, scene, with_background


@pytest.mark.parametrize("background", [0.0, np.inf])
def test_torch_twin_accepts_renderer_background_like_the_jax_model(background):
    torch = pytest.importorskip("torch")
    import invsss.torch as itorch

    image, depth, mask = scene()
    p = PARAMS
    twin = itorch.SSSParams(
        float(p.sss_level), float(p.correction), float(p.maxdd),
        np.asarray(p.weights).tolist(), np.asarray(p.variances).tolist(),
    )
    renderer_depth = with_background(depth, mask, background)
    expected = itorch.render(torch.as_tensor(image), torch.as_tensor(depth), torch.as_tensor(mask), twin)
    got = itorch.render(torch.as_tensor(image), torch.as_tensor(renderer_depth), torch.as_tensor(mask), twin)
    assert torch.isfinite(got).all()
    np.testing.assert_allclose(got.numpy()[mask > 0], expected.numpy()[mask > 0], rtol=1e-12)
    # ... and agrees with the JAX model given the same renderer-style depth.
    jax_out = np.asarray(invsss.render(image, renderer_depth, mask, PARAMS))
    np.testing.assert_allclose(got.numpy(), jax_out, rtol=1e-4, atol=1e-6)
