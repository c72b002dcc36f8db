"""Every model of the table (invsss.forward.models) in every layer that renders or
writes it: the JAX renderer, the PyTorch twin, and the exported shader constants."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import invsss
from invsss.forward.models import MODEL_NAMES, get_model
from tests.forward._model_table import BASE, expected_plan, scene, spread


@pytest.mark.slow
@pytest.mark.parametrize("name", MODEL_NAMES)
def test_every_model_renders_in_both_frameworks_and_exports(name):
    torch = pytest.importorskip("torch")
    pytest.importorskip("kornia")
    import invsss.torch as itorch

    image, depth, mask = scene()
    with jax.enable_x64(True):
        p = invsss.SSSParams(**BASE)
        out = np.asarray(invsss.render(image, depth, mask, p, model=name))
    twin = itorch.render(
        torch.tensor(image), torch.tensor(depth), torch.tensor(mask),
        itorch.SSSParams(**{k: torch.tensor(v, dtype=torch.float64) for k, v in BASE.items()}), model=name,
    )
    np.testing.assert_allclose(twin.detach().numpy(), out, rtol=0, atol=1e-9)
    assert not np.allclose(out, image)  # the model did blur

    constants = invsss.shader_constants(invsss.SSSParams(**BASE), name)
    assert constants["model"] == name
    entry = get_model(name)
    if entry.layout == "kernel":
        assert "passWidths" not in constants and constants["numTaps"] == 17
    elif entry.layout == "disk":
        np.testing.assert_allclose(constants["shapeParameters"], np.sqrt(BASE["variances"]), rtol=1e-14)
    else:
        # One width per Gaussian, in pass order, from docs/model.md's formula.
        _, widths, _ = expected_plan(entry.layout, BASE["variances"], spread(entry.default_tap_weights))
        np.testing.assert_allclose(constants["passWidths"], widths[1::2] if entry.layout == "layered"
                                   else widths[: len(BASE["variances"])], rtol=1e-14)
        assert constants["tapWeightSet"] == entry.default_tap_weights
    assert "static const" in invsss.to_hlsl(constants)
