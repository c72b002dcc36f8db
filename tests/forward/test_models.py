"""The model table (invsss.forward.models) and the shared pass plan (invsss.forward.pass_plan).

What the table claims about a model is checked against what the model does:
its parameter set against which parameters change the rendered image, its
default tap set against ``render`` with no tap set, its layout against the
JAX renderer (and, in tests/test_models.py, against the PyTorch twin and the
export). The pass widths are checked against docs/model.md's formulas written out
with plain Python loops (tests/forward/_model_table.py).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.forward.models import MODEL_NAMES, MODEL_TABLE, MODELS, ScreenSpaceModel, get_model, resolve_tap_weights
from invsss.forward.params import PARAM_NAMES
from invsss.forward.pass_plan import pass_plan
from invsss.validation import InvalidInputError
from tests.forward._model_table import BASE, CHANGED, TAPS, expected_plan, scene, spread


# ------------------------------------------------------------------ the table


def test_table_names_and_lookup():
    assert MODEL_NAMES == tuple(MODELS) == ("sog", "thesis", "separable", "burley")
    assert invsss.MODELS == invsss.forward.screen_space.MODELS == MODEL_NAMES
    for name in MODEL_NAMES:
        assert get_model(name).name == name
    # docs/model.md, sections 3 and 5: jimenez is the default set, the thesis shipped its own.
    defaults = {name: m.default_tap_weights for name, m in MODEL_TABLE.items()}
    assert defaults == {"sog": "jimenez", "thesis": "thesis", "separable": None, "burley": None}
    with pytest.raises(InvalidInputError, match=r"^model: expected one of sog, thesis, separable, burley, got 'x'$"):
        get_model("x")
    with pytest.raises(InvalidInputError, match="model: expected one of"):
        invsss.render(*scene(), invsss.SSSParams(**BASE), model="x")


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_parameters_are_the_ones_that_change_the_image(name):
    image, depth, mask = scene()
    base = np.asarray(invsss.render(image, depth, mask, invsss.SSSParams(**BASE), model=name))
    changed = set()
    for k in PARAM_NAMES:
        out = invsss.render(image, depth, mask, invsss.SSSParams(**{**BASE, k: CHANGED[k]}), model=name)
        diff = np.max(np.abs(np.asarray(out) - base))
        if diff > 1e-4:
            changed.add(k)
        else:  # a parameter outside the model must not enter it at all
            assert diff == 0.0, (k, diff)
    assert changed == set(get_model(name).parameters)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_default_taps_come_from_the_table(name):
    image, depth, mask = scene()
    p = invsss.SSSParams(**BASE)
    default = np.asarray(invsss.render(image, depth, mask, p, model=name))
    entry = get_model(name)
    for spec in TAPS:
        out = np.asarray(invsss.render(image, depth, mask, p, model=name, tap_weights=spec))
        # The kernel layout has no 7-tap passes: no tap set changes it.
        same = spec == entry.default_tap_weights or entry.default_tap_weights is None
        assert np.array_equal(out, default) == same, spec
    assert resolve_tap_weights(name) == entry.default_tap_weights
    assert resolve_tap_weights(name, "thesis") == (None if entry.default_tap_weights is None else "thesis")


def test_a_bad_entry_is_caught_when_written():
    sog = get_model("sog")
    for change in (
        {"parameters": frozenset({"sss_level", "blur"})},
        {"weights_role": "unused"},  # weights are in its parameters
        {"layout": "spiral"},
        {"layout": "chained"},  # linear weights need the layered layout
        {"default_tap_weights": None},  # 7-tap passes need a default tap set
    ):
        with pytest.raises(ValueError):
            dataclasses.replace(sog, **change)
    assert isinstance(dataclasses.replace(sog, name="sog2"), ScreenSpaceModel)


# ------------------------------------------------------------------ the pass plan


def namespaces():
    # jnp runs under x64 (see the test): in float32, v_i - v_{i-1} of two close
    # variances loses most of its digits.
    out = [(np, np.asarray), (jnp, lambda v: jnp.asarray(v, jnp.float64))]
    try:
        import torch

        out.append((torch, lambda v: torch.tensor(v, dtype=torch.float64)))
    except ImportError:  # the twin is optional
        pass
    return out


@pytest.mark.parametrize("layout", ["layered", "chained"])
@pytest.mark.parametrize("variances", [[8.749, 2.099, 0.549, 0.5574, 1.194], [2.0, 0.0, 2.0, 0.5]])
@pytest.mark.parametrize("taps", ["jimenez", "thesis"])
def test_pass_plan_matches_the_formulas(layout, variances, taps):
    c_w = spread(taps)
    axes, widths, order = expected_plan(layout, variances, c_w)
    for xp, asarray in namespaces():
        with jax.enable_x64(True):
            plan = pass_plan(layout, asarray(variances), c_w, xp)
        assert plan.axes == axes, xp.__name__
        assert np.asarray(plan.widths).dtype == np.float64, xp.__name__
        np.testing.assert_allclose(np.asarray(plan.widths), widths, rtol=1e-14, atol=0, err_msg=xp.__name__)
        if order is None:
            assert plan.order is None
        else:
            assert np.asarray(plan.order).tolist() == order, xp.__name__
    with pytest.raises(ValueError, match="layout"):
        pass_plan("kernel", np.asarray(variances), c_w, np)


def test_tap_spread_matches_model_md():
    # docs/model.md, section 3: c_W = 0.34641 (jimenez) and 0.61008 (thesis).
    assert spread("jimenez") == pytest.approx(0.34641, abs=5e-6)
    assert spread("thesis") == pytest.approx(0.61008, abs=5e-6)
    for name in TAPS:
        with jax.enable_x64(True):
            got = float(invsss.tap_spread(invsss.tap_weights(name)))
        assert got == pytest.approx(spread(name), rel=1e-14)


def test_torch_gradients_flow_through_the_plan():
    torch = pytest.importorskip("torch")
    v = torch.tensor([2.0, 0.5, 3.0], dtype=torch.float64, requires_grad=True)
    for layout in ("layered", "chained"):
        assert torch.autograd.gradcheck(lambda v: pass_plan(layout, v, 0.4, torch).widths, (v,))
