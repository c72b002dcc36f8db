"""The ``law`` light term's PyTorch twin (invsss.torch.apply_law) against the JAX model:
values and gradients, and torch's gradcheck."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from invsss.forward.light_terms import LightBuffers, apply_law
from tests.forward._lit_scenes import H, W, law_scene

pytestmark = pytest.mark.usefixtures("float64")


class TestTorchTwin:
    torch = pytest.importorskip("torch")

    def test_values_and_gradients_agree(self):
        torch = self.torch
        import invsss.torch as itorch

        source, key, _, mask, normal, light = law_scene(5)
        weights = np.random.default_rng(6).normal(size=(H, W, 3))
        w0 = np.array([0.93, 0.8, 0.55])

        def jax_f(w):
            out = apply_law(source, mask, w, LightBuffers(normal, light, key))
            return jnp.sum(jnp.asarray(weights) * out), out

        (_, out_jax), grad_jax = jax.value_and_grad(jax_f, has_aux=True)(jnp.asarray(w0))
        t = lambda a: torch.as_tensor(np.array(a), dtype=torch.float64)  # noqa: E731
        w = torch.tensor(w0, dtype=torch.float64, requires_grad=True)
        out_torch = itorch.apply_law(t(source), t(mask), w, t(normal), t(light), t(key))
        (t(weights) * out_torch).sum().backward()
        np.testing.assert_allclose(out_torch.detach().numpy(), np.asarray(out_jax), rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(w.grad.numpy(), np.asarray(grad_jax), rtol=1e-10)

    def test_gradcheck(self):
        torch = self.torch
        import invsss.torch as itorch

        source, key, _, mask, normal, light = law_scene(7)
        t = lambda a: torch.as_tensor(np.array(a), dtype=torch.float64)  # noqa: E731

        def f(w):
            return itorch.apply_law(t(source), t(mask), w, t(normal), t(light), t(key))

        w = torch.tensor([0.91, 0.6, 0.3], dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(f, (w,))
