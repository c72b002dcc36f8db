"""The ``transmission`` term's PyTorch twin (invsss.torch.apply_transmission) against the JAX
model: values and gradients, and torch's gradcheck."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from invsss.forward.light_terms import LightTerms
from invsss.forward.transmission import apply_transmission
from tests.forward._backlit_scenes import backlit_dome

pytestmark = pytest.mark.usefixtures("float64")
torch = pytest.importorskip("torch")


def _tensors(buffers, source, mask):
    import invsss.torch as itorch  # noqa: F401  (the twin under test)

    as_t = {name: torch.tensor(np.asarray(getattr(buffers, name)), dtype=torch.float64)
            for name in ("thickness", "key_irradiance", "normal", "light")}
    return torch.tensor(source), torch.tensor(mask), as_t


def test_values_and_gradients_agree():
    import invsss.torch as itorch

    source, _, mask, buffers = backlit_dome(channels=3)
    weights = np.random.default_rng(5).normal(size=source.shape)
    x0 = np.array([0.9, 0.4, 0.2, 0.12])

    def jax_f(x):
        out = apply_transmission(jnp.asarray(source), jnp.asarray(mask),
                                 LightTerms(transmission=x[:3], thickness_scale=x[3]), buffers)
        return jnp.sum(jnp.asarray(weights) * out), out

    (value, out_jax), grad_jax = jax.value_and_grad(jax_f, has_aux=True)(jnp.asarray(x0))
    image, m, b = _tensors(buffers, source, mask)
    x = torch.tensor(x0, requires_grad=True)
    out = itorch.apply_transmission(image, m, x[:3], x[3], b["thickness"], b["key_irradiance"], b["normal"],
                                    b["light"])
    (torch.tensor(weights) * out).sum().backward()
    np.testing.assert_allclose(out.detach().numpy(), np.asarray(out_jax), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(x.grad.numpy(), np.asarray(grad_jax), rtol=1e-10)
    assert float(np.abs(out.detach().numpy() - source).max()) > 0.01  # the term did something


def test_gradcheck():
    import invsss.torch as itorch

    source, _, mask, buffers = backlit_dome(size=8, channels=1)
    image, m, b = _tensors(buffers, source, mask)
    tint = torch.tensor([0.6], dtype=torch.float64, requires_grad=True)
    scale = torch.tensor(0.2, dtype=torch.float64, requires_grad=True)
    thickness = b["thickness"].clone().requires_grad_(True)

    def f(tint, scale, thickness):
        return itorch.apply_transmission(image, m, tint, scale, thickness, b["key_irradiance"], b["normal"],
                                         b["light"])

    assert torch.autograd.gradcheck(f, (tint, scale, thickness))
