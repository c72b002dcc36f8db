"""The light-aware terms' PyTorch twin (invsss.torch.apply_light_terms, shift_image)
against the JAX model: values and gradients, and torch's gradcheck."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_light_terms
from tests.forward._lit_scenes import H, W, light_terms_scene, unit

pytestmark = pytest.mark.usefixtures("float64")


class TestTorchTwin:
    torch = pytest.importorskip("torch")

    def test_values_and_gradients_agree(self):
        torch = self.torch
        import invsss.torch as itorch

        image, depth, mask, light, normal, params = light_terms_scene(1)
        blurred = np.asarray(invsss.render(image, depth, mask, params))
        x0 = np.array([1.37, 0.21, 810.0, 0.33])
        weights = np.random.default_rng(4).normal(size=(H, W, 3))

        def jax_f(x):
            p = invsss.SSSParams(x[2], params.correction, params.maxdd, params.weights, params.variances)
            out = apply_light_terms(jnp.asarray(blurred), jnp.asarray(depth), jnp.asarray(mask), p,
                                    LightTerms(shift=x[0], grazing=x[1], incidence=x[3]),
                                    LightBuffers(normal=jnp.asarray(normal), light=jnp.asarray(light)))
            return jnp.sum(jnp.asarray(weights) * out), out

        (value, out_jax), grad_jax = jax.value_and_grad(jax_f, has_aux=True)(jnp.asarray(x0))

        x = torch.tensor(x0, dtype=torch.float64, requires_grad=True)
        p = itorch.SSSParams(x[2], float(params.correction), float(params.maxdd),
                             np.array(params.weights), np.array(params.variances))
        t = lambda a: torch.as_tensor(np.array(a), dtype=torch.float64)  # noqa: E731
        out_torch = itorch.apply_light_terms(t(blurred), t(depth), t(mask), p, shift=x[0], grazing_gain=x[1],
                                             normal=t(normal), light=t(light), incidence_gain=x[3])
        (t(weights) * out_torch).sum().backward()
        np.testing.assert_allclose(out_torch.detach().numpy(), np.asarray(out_jax), atol=1e-12)
        np.testing.assert_allclose(x.grad.numpy(), np.asarray(grad_jax), rtol=1e-9, atol=1e-12)

    def test_gradcheck(self):
        torch = self.torch
        import invsss.torch as itorch

        rng = np.random.default_rng(2)
        image = torch.tensor(rng.uniform(size=(6, 8, 1)), dtype=torch.float64)
        light = torch.tensor(unit(rng.normal(size=(6, 8, 3)) + [0, 0, 2]), dtype=torch.float64)
        offsets = itorch.propagation_offsets(light)

        def f(kappa):
            return itorch.shift_image(image, kappa * offsets)

        assert torch.autograd.gradcheck(f, (torch.tensor(0.731, dtype=torch.float64, requires_grad=True),))
