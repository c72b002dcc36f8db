"""The ``fill`` light term's PyTorch twin (invsss.torch.apply_law) against the JAX model."""

from __future__ import annotations

import numpy as np
import pytest

from invsss.forward.light_terms import LightBuffers, apply_law
from tests.forward._lit_scenes import fill_scene

pytestmark = pytest.mark.usefixtures("float64")


def test_the_pytorch_twin_matches():
    torch = pytest.importorskip("torch")
    import invsss.torch as itorch

    source, key, _, mask, normal, light, fill_light = fill_scene(4)
    w = [0.93, 0.8, 0.55]
    out_jax = apply_law(source, mask, w, LightBuffers(normal, light, key, fill_light), 0.8, 0.6)
    t = lambda a: torch.as_tensor(np.array(a), dtype=torch.float64)  # noqa: E731
    out_torch = itorch.apply_law(t(source), t(mask), t(w), t(normal), t(light), t(key), 0.8, t(fill_light), 0.6)
    np.testing.assert_allclose(out_torch.numpy(), np.asarray(out_jax), rtol=1e-13, atol=1e-14)
