"""The model table read by the estimator: each model's roles of the parameters, and
the data scales' largest stretch, which is the stretch the model renders with."""

from __future__ import annotations

import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.estimator.initial import data_scales
from invsss.estimator.parametrisation import assign_roles
from invsss.forward.models import MODEL_TABLE
from tests.forward._model_table import scene


def test_estimator_roles_follow_the_table():
    for name, entry in MODEL_TABLE.items():
        roles = assign_roles(name, "variances", {})
        assert roles["weights"] == entry.weights_role
        for k in ("correction", "maxdd"):
            assert roles[k] == ("free" if k in entry.parameters else "unused")
        assert assign_roles(name, "variances", {"weights": np.ones(2)})["weights"] == "fixed"


def test_data_scales_max_stretch_is_the_render_stretch():
    image, depth, mask = scene()
    mask[:, :3] = 0.0  # the steepest masked pixels decide, not the masked-out ones
    pair = types.SimpleNamespace(depth=depth, mask=mask)
    with jax.enable_x64(True):
        scales = data_scales([pair])
        for c, delta in ((50.0, 3.0), (0.0, 1.0), (200.0, 0.1)):
            s_x, s_y = invsss.stretch_factors(jnp.asarray(depth), 600.0, c, delta)
            want = max(np.asarray(s_x)[mask > 0].max(), np.asarray(s_y)[mask > 0].max())
            assert scales.max_stretch(600.0, c, delta) == pytest.approx(want, rel=1e-12)
