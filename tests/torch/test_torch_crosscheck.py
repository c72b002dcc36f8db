"""Cross-check of the JAX forward model against its PyTorch twin (invsss.torch).

Both implement docs/model.md independently where it matters (JAX: flat gather with
explicit clamping; torch: kornia remap / grid_sample with border padding), so
agreement to rounding in float64, of the outputs and of the gradients with
respect to every parameter and the image, checks each against the other. The
twin's own derivatives are checked against finite differences (gradcheck).

Relative error: ``max|a - b| / max|b|`` over an array (output, image gradient);
each parameter entry (every weight, every variance) is compared on its own.
"""

from __future__ import annotations

import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("kornia")

import invsss  # noqa: E402
import invsss.torch as itorch  # noqa: E402
from invsss.validation import InvalidInputError  # noqa: E402

RTOL = 1e-6
FIELDS = ("sss_level", "correction", "maxdd", "weights", "variances")


# --------------------------------------------------------------------------- scenes


def make_scene(seed, h=20, w=24, channels=3, per_channel=False, degenerate=False):
    """Random image, smooth positive depth, partial fractional mask and random params.

    ``channels=None`` gives an (H, W) image. ``maxdd`` is a random quantile of the
    depth slopes, so the ``min(|dd|, maxdd)`` of the stretch factors is active on
    some pixels and not on others. ``degenerate`` adds a zero variance and repeats
    one: zero-width (identity) passes, whose footprint derivative both sides take
    as 0 (the JAX ``_safe_sqrt``), and a tie that only a stable sort orders alike.
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = np.full((h, w), 500.0)
    for _ in range(3):
        kx, ky = rng.uniform(-0.5, 0.5, 2)
        depth += rng.uniform(2.0, 8.0) * np.sin(kx * xx + ky * yy + rng.uniform(0, 2 * np.pi))
    ddy, ddx = np.gradient(depth)
    slopes = np.abs(np.concatenate([ddx.ravel(), ddy.ravel()]))
    maxdd = float(np.quantile(slopes, rng.uniform(0.3, 0.7)))
    phase = rng.uniform(0, 2 * np.pi, 2)
    mask = np.clip(0.5 + 0.9 * np.sin(0.35 * xx + phase[0]) * np.cos(0.3 * yy + phase[1]), 0.0, 1.0)
    shape = (h, w) if channels is None else (h, w, channels)
    image = rng.uniform(0.05, 1.0, shape)
    k = int(rng.integers(3, 6))
    weights = rng.uniform(0.1, 1.0, (k, channels) if per_channel else (k,))
    params = {
        "sss_level": rng.uniform(600.0, 1200.0),
        "correction": rng.uniform(0.2, 0.6) * 500.0 / maxdd,
        "maxdd": maxdd,
        "weights": weights,
        "variances": rng.uniform(0.05, 1.5, k),
    }
    if degenerate:
        v = params["variances"]
        params["variances"] = np.concatenate([[v[0], 0.0, v[0]], v[1:]])
        params["weights"] = np.concatenate([weights[:2], weights])
    probe = rng.normal(size=shape)  # the linear functional sum(probe * out)
    return {"image": image, "depth": depth, "mask": mask, "params": params, "probe": probe}


def jax_render_and_grads(scene, model, extras):
    """Output and gradients of ``sum(probe * render)`` from the JAX core, float64.

    ``extras`` are keyword arguments of render; array-valued ones are differentiated.
    """
    with jax.enable_x64(True):
        p = invsss.SSSParams(**scene["params"])
        image = jnp.asarray(scene["image"])
        depth, mask = jnp.asarray(scene["depth"]), jnp.asarray(scene["mask"])
        probe = jnp.asarray(scene["probe"])
        arrays = {k: jnp.asarray(v) for k, v in extras.items() if isinstance(v, np.ndarray)}
        fixed = {k: v for k, v in extras.items() if not isinstance(v, np.ndarray)}

        def functional(p, image, arrays, depth, mask, probe):
            out = invsss.render(image, depth, mask, p, model, **fixed, **arrays)
            return jnp.sum(probe * out), out

        # One compiled program per case (XLA's compile time dominates this file);
        # the scene goes in as arguments, not as constants for XLA to fold. Tracing
        # render in the image also guards the fixed check_image-on-tracers bug.
        grad_fn = jax.jit(jax.grad(functional, argnums=(0, 1, 2), has_aux=True))
        (gp, gimage, garrays), out = grad_fn(p, image, arrays, depth, mask, probe)
        result = {k: np.asarray(getattr(gp, k)) for k in FIELDS}
        result.update({k: np.asarray(v) for k, v in garrays.items()})
        result["image"] = np.asarray(gimage)
        return np.asarray(out), result


def torch_render_and_grads(scene, model, extras):
    """The same from invsss.torch with autograd, float64."""
    leaves = {
        k: torch.tensor(np.asarray(v), dtype=torch.float64, requires_grad=True)
        for k, v in scene["params"].items()
    }
    image = torch.tensor(scene["image"], dtype=torch.float64, requires_grad=True)
    arrays = {
        k: torch.tensor(v, dtype=torch.float64, requires_grad=True)
        for k, v in extras.items()
        if isinstance(v, np.ndarray)
    }
    fixed = {k: v for k, v in extras.items() if not isinstance(v, np.ndarray)}
    out = itorch.render(
        image, torch.tensor(scene["depth"]), torch.tensor(scene["mask"]),
        itorch.SSSParams(**leaves), model, **fixed, **arrays,
    )
    (torch.tensor(scene["probe"]) * out).sum().backward()
    grads = {**leaves, **arrays, "image": image}
    # A parameter the model does not use (e.g. weights in `thesis`) gets no grad: 0.
    result = {
        k: (t.grad.numpy() if t.grad is not None else np.zeros(t.shape)) for k, t in grads.items()
    }
    return out.detach().numpy(), result


def relative_error(a, b):
    scale = np.max(np.abs(b))
    diff = np.max(np.abs(a - b))
    return diff / scale if scale > 0 else diff


def assert_entries_agree(name, got, want):
    """Every entry of a parameter gradient: relative error <= RTOL on its own."""
    got, want = np.atleast_1d(got), np.atleast_1d(want)
    assert got.shape == want.shape, name
    for idx in np.ndindex(want.shape):
        g, w = got[idx], want[idx]
        # An exact zero on one side (a parameter the model ignores) must be exact on both.
        bound = RTOL * abs(w) if w != 0 else 0.0
        assert abs(g - w) <= bound, f"d/d{name}{list(idx)}: torch {g!r} vs jax {w!r}"


def assert_twins_agree(scene, model, extras=None):
    extras = extras or {}
    out_j, grads_j = jax_render_and_grads(scene, model, extras)
    out_t, grads_t = torch_render_and_grads(scene, model, extras)
    assert out_t.shape == out_j.shape == scene["image"].shape
    # The model must do something on this scene, or agreement would be vacuous.
    assert relative_error(out_j, scene["image"]) > 1e-2
    assert relative_error(out_t, out_j) <= RTOL
    assert relative_error(grads_t["image"], grads_j["image"]) <= RTOL
    for name in grads_j:
        if name != "image":
            assert_entries_agree(name, grads_t[name], grads_j[name])
    return grads_j


# --------------------------------------------------------------------------- cross-checks

CASES = [
    # (model, seed, channels, per-channel weights, degenerate variances, render extras);
    # channels None is an (H, W) image, i.e. one channel through render's squeeze.
    ("sog", 1, 3, True, False, {"tap_weights": "thesis"}),
    ("sog", 2, None, False, True, {}),
    ("thesis", 3, 1, False, False, {}),
    ("thesis", 4, 3, True, True, {"tap_weights": "jimenez"}),
    ("separable", 5, 3, False, False, {}),
    ("separable", 6, 3, True, False,
     {"taps": 11, "strength": np.array([0.6, 0.8, 0.9]), "follow_surface": np.array(0.15)}),
    ("separable", 7, None, False, False, {"taps": 13, "strength": np.array(0.7)}),
]


@pytest.mark.slow
@pytest.mark.parametrize(
    "model, seed, channels, per_channel, degenerate, extras", CASES,
    ids=[f"{c[0]}-{c[1]}" for c in CASES],
)
def test_outputs_and_gradients_agree(model, seed, channels, per_channel, degenerate, extras):
    scene = make_scene(seed, channels=channels, per_channel=per_channel, degenerate=degenerate)
    slopes = np.abs(np.stack(np.gradient(scene["depth"])))
    delta = scene["params"]["maxdd"]
    assert np.any(slopes > delta) and np.any(slopes < delta)
    assert np.any(scene["mask"] == 0) and np.any((scene["mask"] > 0) & (scene["mask"] < 1))
    grads = assert_twins_agree(scene, model, extras)
    # The parameters each model uses really move its output (in `thesis` a zero
    # variance has zero derivative by the identity-pass convention).
    used = {"sog": FIELDS, "thesis": ("sss_level", "correction", "maxdd", "variances"),
            "separable": ("sss_level", "weights", "variances")}[model]
    for name in used:
        g = grads[name]
        if name == "variances":
            g = g[scene["params"]["variances"] != 0]
        assert np.all(g != 0), name
    for name in set(FIELDS) - set(used):
        assert np.all(grads[name] == 0), name


@pytest.mark.slow
def test_separable_kernel_agrees():
    rng = np.random.default_rng(13)
    weights, variances = rng.uniform(0.1, 1.0, (4, 3)), rng.uniform(0.05, 2.0, 4)
    strength = np.array([0.3, 0.9, 1.0])
    for taps in (11, 25):
        with jax.enable_x64(True):
            oj, kj = invsss.separable_kernel(jnp.asarray(weights), jnp.asarray(variances), taps, jnp.asarray(strength))
            oj, kj = np.asarray(oj), np.asarray(kj)
        ot, kt = itorch.separable_kernel(torch.tensor(weights), torch.tensor(variances), taps, torch.tensor(strength))
        assert ot.shape == (taps,) and kt.shape == (taps, 3)
        np.testing.assert_allclose(ot.numpy(), oj, rtol=0, atol=1e-14)
        assert relative_error(kt.numpy(), kj) <= RTOL


def test_stretch_factors_agree():
    scene = make_scene(14)
    p = scene["params"]
    with jax.enable_x64(True):
        sj = invsss.stretch_factors(jnp.asarray(scene["depth"]), p["sss_level"], p["correction"], p["maxdd"])
        sj = [np.asarray(s) for s in sj]
    st = itorch.stretch_factors(torch.tensor(scene["depth"]), p["sss_level"], p["correction"], p["maxdd"])
    for a, b in zip(st, sj):
        assert relative_error(a.numpy(), b) <= RTOL


# --------------------------------------------------------------------------- finite differences


@pytest.mark.slow
@pytest.mark.parametrize("model", ["sog", "thesis", "separable"])
def test_gradcheck_parameters(model):
    # Generic random values on a tiny scene: no tap lands exactly on a pixel
    # centre and no slope equals maxdd, so the model is smooth around this point.
    scene = make_scene(20 + len(model), h=12, w=12, channels=3, per_channel=True)
    depth, mask = torch.tensor(scene["depth"]), torch.tensor(scene["mask"])
    image = torch.tensor(scene["image"])
    leaves = [torch.tensor(np.asarray(scene["params"][k]), dtype=torch.float64, requires_grad=True) for k in FIELDS]
    if model == "separable":
        leaves += [torch.tensor(0.8, dtype=torch.float64, requires_grad=True),
                   torch.tensor(0.12, dtype=torch.float64, requires_grad=True)]

    def f(*args):
        extras = {"strength": args[5], "follow_surface": args[6]} if model == "separable" else {}
        return itorch.render(image, depth, mask, itorch.SSSParams(*args[:5]), model, **extras)

    assert torch.autograd.gradcheck(f, tuple(leaves), eps=1e-6, atol=1e-7, rtol=1e-4)


# --------------------------------------------------------------------------- API


def test_identity_for_empty_mask_region_and_shapes():
    scene = make_scene(30, channels=None)
    p = itorch.SSSParams(**scene["params"])
    image = torch.tensor(scene["image"])
    out = itorch.render(image, scene["depth"], scene["mask"], p)
    assert out.shape == image.shape and out.dtype == torch.float64
    off = scene["mask"] == 0
    assert torch.equal(out[off], image[off])


def _message(fn):
    with pytest.raises(InvalidInputError) as err:
        fn()
    return str(err.value)


BAD_INPUTS = {
    "image channels": lambda s: {"image": np.zeros((20, 24, 4))},
    "image dtype": lambda s: {"image": np.zeros((20, 24, 3), np.int32)},
    "image nan": lambda s: {"image": np.where(s["image"] > 0.5, np.nan, s["image"])},
    "depth shape": lambda s: {"depth": s["depth"][:-1]},
    "depth zero": lambda s: {"depth": np.where(s["mask"] > 0.9, 0.0, s["depth"])},
    "mask range": lambda s: {"mask": s["mask"] * 2},
    "mask empty": lambda s: {"mask": np.zeros_like(s["mask"])},
    "model": lambda s: {"model": "dipole"},
    "weights columns": lambda s: {"weights": np.ones((len(s["params"]["variances"]), 2))},
    "negative variance": lambda s: {"variances": -s["params"]["variances"]},
    "zero sss_level": lambda s: {"sss_level": 0.0},
    "tap weights": lambda s: {"tap_weights": "flat"},
    "even taps": lambda s: {"model": "separable", "taps": 16},
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_invalid_input_messages_match_jax(case):
    scene = make_scene(31)
    change = BAD_INPUTS[case](scene)
    args = {"image": scene["image"], "depth": scene["depth"], "mask": scene["mask"], "model": "sog"}
    params = dict(scene["params"])
    kwargs = {}
    for k, v in change.items():
        if k in args:
            args[k] = v
        elif k in params:
            params[k] = v
        else:
            kwargs[k] = v
    jax_msg = _message(lambda: invsss.render(
        args["image"], args["depth"], args["mask"], invsss.SSSParams(**params), args["model"], **kwargs))
    torch_msg = _message(lambda: itorch.render(
        args["image"], args["depth"], args["mask"], itorch.SSSParams(**params), args["model"], **kwargs))
    assert torch_msg == jax_msg
    assert "\n" not in torch_msg


def test_params_type_and_dict_round_trip():
    scene = make_scene(32)
    jax_params = invsss.SSSParams(**scene["params"])
    message = _message(lambda: itorch.render(scene["image"], scene["depth"], scene["mask"], jax_params))
    assert message == "params: expected invsss.torch.SSSParams, got SSSParams"
    p = itorch.SSSParams.from_dict(jax_params.to_dict())
    for k in FIELDS:
        np.testing.assert_allclose(p.to_dict()[k], jax_params.to_dict()[k], rtol=1e-6)
    assert _message(lambda: itorch.SSSParams.from_dict({"sss_level": 1.0})) == (
        "params: missing key(s) correction, maxdd, weights, variances"
    )


def test_import_invsss_does_not_import_torch():
    code = "import sys, invsss; sys.exit(int('torch' in sys.modules or 'kornia' in sys.modules))"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0



def test_params_shapes_checked_at_the_boundary():
    # A weight without a variance, or a list where a number belongs, is an error
    # with the same one-line message in both implementations, not silently dropped.
    scene = make_scene(33)
    k = len(scene["params"]["variances"])
    for bad in (
        dict(scene["params"], weights=np.ones(k + 1)),
        dict(scene["params"], sss_level=[800.0, 900.0]),
        dict(scene["params"], variances=[scene["params"]["variances"]]),
    ):
        torch_message = _message(lambda: itorch.render(
            scene["image"], scene["depth"], scene["mask"], itorch.SSSParams(**bad)))
        jax_message = _message(lambda: invsss.render(
            scene["image"], scene["depth"], scene["mask"], invsss.SSSParams(**bad)))
        assert torch_message == jax_message
        assert torch_message.startswith("params: ") and "\n" not in torch_message
