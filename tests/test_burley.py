"""The ``burley`` model (issue 34): its sample pattern and weights, its PyTorch twin,
its gradients, its recovery by ``invsss fit`` and its export as the engines' profiles."""

from __future__ import annotations

import io
import json
from contextlib import redirect_stderr, redirect_stdout

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import invsss
from invsss.forward.burley_screen_space import burley_cdf, render_burley, unit_radii
from invsss.cli import main
from invsss.io.engine_profiles import (
    engine_profile,
    hdrp_distances,
    hdrp_profile,
    perpendicular_scaling,
    unreal_distances,
    unreal_profile,
)
from invsss.validation import InvalidInputError
from _pair_files import pair_args, write_pair

D = np.array([1.1, 0.55, 0.3])  # Burley's d per channel, mm: red scatters furthest, as in skin


def burley_params(d=D, level=800.0):
    d = d if isinstance(d, jax.Array) else np.asarray(d, np.float64)  # traced under jax.grad
    return invsss.SSSParams(level, 0.0, 1.0, np.ones(d.shape[0]), d**2)


def small_scene(seed=0, h=20, w=24):
    """Random image, rippled depth (mm) and a fractional mask with zeros."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 500.0 + 6.0 * np.sin(0.4 * xx + 0.2 * yy) + 0.8 * xx
    mask = np.clip(0.5 + 0.9 * np.sin(0.35 * xx + 1.0) * np.cos(0.3 * yy), 0.0, 1.0)
    image = rng.uniform(0.05, 1.0, (h, w, 3))
    probe = rng.normal(size=(h, w, 3))
    return image, depth, mask, probe


# ------------------------------------------------------------------ pattern and weights


def test_unit_radii_invert_the_cdf_where_bisection_does():
    n = 16
    x = unit_radii(n)
    targets = (np.arange(n) + 0.5) / n
    lo, hi = np.zeros(n), np.full(n, 100.0)
    for _ in range(200):  # bisection: an independent inverse of the increasing CDF
        mid = 0.5 * (lo + hi)
        below = burley_cdf(mid) < targets
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    np.testing.assert_allclose(x, 0.5 * (lo + hi), rtol=1e-10)


def test_each_channel_blurs_with_its_own_profile():
    """A radial kernel multiplies ``cos(k x)`` by its Hankel transform; for Burley's
    profile ``H(k) = (1 / sqrt(1 + k^2 d^2) + 3 / sqrt(1 + 9 k^2 d^2)) / 4``. At the pixel
    where ``I = cos(k (x - x0)) + cos(k (y - y0))`` peaks, the blur returns ``2 H_c(k)``.
    Only the widest channel is importance sampled; the others must get their own
    profile through their weights (with the widest one's, blue would give 1.42, not 1.85)."""
    size, centre, k = 101, 50, 0.2
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    image = (np.cos(k * (xx - centre)) + np.cos(k * (yy - centre)))[..., None].repeat(3, axis=-1)
    d = np.array([2.0, 1.0, 0.6])  # mm, and px: sss_level / depth = 1 px per mm
    with jax.enable_x64(True):
        out = render_burley(jnp.asarray(image), jnp.full((size, size), 500.0), jnp.ones((size, size)),
                            burley_params(d, level=500.0), samples=512)
    hankel = (1.0 / np.sqrt(1.0 + (k * d) ** 2) + 3.0 / np.sqrt(1.0 + 9.0 * (k * d) ** 2)) / 4.0
    np.testing.assert_allclose(np.asarray(out)[centre, centre], 2.0 * hankel, rtol=0.01)


def test_a_constant_stays_and_bad_distances_are_refused():
    image, depth, mask, _ = small_scene()
    flat = np.full_like(image, 0.7)
    out = invsss.render(flat, depth, mask, burley_params(), model="burley")
    np.testing.assert_allclose(np.asarray(out), 0.7, rtol=1e-6)
    with pytest.raises(InvalidInputError, match=r"^params.variances: the burley model takes d\^2 for one channel"):
        invsss.render(image, depth, mask, invsss.SSSParams(800.0, 0.0, 1.0, [1.0, 1.0], [1.0, 0.5]),
                      model="burley")


# ------------------------------------------------------------------ gradients and the twin


def burley_functional(image, depth, mask, probe):
    """``(d, level, image) -> (sum(probe * render), render)``, compiled once (float64)."""
    def functional(d, level, image):
        out = invsss.render(image, depth, mask, burley_params(d, level), model="burley")
        return jnp.sum(jnp.asarray(probe) * out), out

    return jax.jit(functional), jax.jit(jax.grad(functional, argnums=(0, 1, 2), has_aux=True))


@pytest.fixture(scope="module")
def compiled():
    """One scene, its compiled functional and gradient, and the JAX gradients at ``D``
    (shared by the finite-difference and the twin checks: one compilation)."""
    image, depth, mask, probe = small_scene(1)
    with jax.enable_x64(True):
        value, grad = burley_functional(image, depth, mask, probe)
        grads, out = grad(jnp.asarray(D), jnp.asarray(800.0), jnp.asarray(image))
    return {"scene": (image, depth, mask, probe), "value": value, "out": np.asarray(out),
            "grads": [np.asarray(g) for g in grads]}


def test_gradients_match_finite_differences(compiled):
    image = compiled["scene"][0]
    g_d, g_level, _ = compiled["grads"]
    with jax.enable_x64(True):
        def at(d, level):
            return float(compiled["value"](jnp.asarray(d), jnp.asarray(level), jnp.asarray(image))[0])

        for c in range(3):
            step = np.zeros(3)
            step[c] = 1e-6
            fd = (at(D + step, 800.0) - at(D - step, 800.0)) / 2e-6
            assert float(g_d[c]) == pytest.approx(fd, rel=1e-5), c
        fd = (at(D, 800.0 + 1e-3) - at(D, 800.0 - 1e-3)) / 2e-3
    assert float(g_level) == pytest.approx(fd, rel=1e-5)
    assert np.all(g_d != 0) and float(g_level) != 0


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


# ------------------------------------------------------------------ recovery by `invsss fit`


def model_made_pair(size, seed):
    """A textured source on a tilted, curved face-sized surface (mm), blurred by ``D``."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    fine = gaussian_filter(rng.standard_normal((size, size, 3)), (0.8, 0.8, 0))
    coarse = gaussian_filter(rng.standard_normal((size, size, 3)), (4.0, 4.0, 0))
    source = np.clip(0.5 + 0.2 * fine / fine.std() + 0.1 * coarse / coarse.std(), 0.05, None)
    depth = 480.0 + 0.6 * xx + 0.3 * yy + 0.004 * (xx - size / 2) ** 2
    mask = np.ones((size, size))
    mask[:, :4] = 0.0
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(source, depth, mask, burley_params(), model="burley"))
    target = 0.9 * clean + 0.02 + 0.002 * rng.standard_normal(clean.shape)
    return source, target, depth, mask


@pytest.mark.slow
@pytest.mark.parametrize("size", [64, 96])
def test_cli_fit_recovers_the_distances(size, tmp_path):
    # No option but the model: its default gauge ("depth") must measure every channel's d,
    # not hold the start (0.759 mm on each channel before issue 46).
    pair = write_pair(tmp_path, "pair", model_made_pair(size, seed=size))
    out = tmp_path / "fit"
    with redirect_stderr(io.StringIO()), redirect_stdout(io.StringIO()):
        code = main(["fit", *pair_args(pair), "--model", "burley", "--out", str(out)])
    assert code == 0
    result = json.loads((out / "params.json").read_text())
    assert result["gauge"] == "depth" and "variances" not in result["fixed"]
    d = np.sqrt(result["variances"])
    np.testing.assert_allclose(d, D, rtol=0.02)
    assert result["sss_level"] == pytest.approx(800.0, rel=0.02)
    stderr = np.asarray(result["stderr"]["variances"])
    assert stderr.shape == (3,) and np.all(stderr > 0)


# ------------------------------------------------------------------ the engines' profiles


def test_engine_fields_convert_both_ways():
    d = np.array([3.0, 1.4, 0.9])
    hdrp = hdrp_profile(d, world_scale=0.01)
    assert max(hdrp["scatteringDistance"]) == 1.0 and hdrp["worldScale"] == 0.01
    np.testing.assert_allclose(hdrp_distances(hdrp), d, rtol=1e-14)
    albedo = [0.9, 0.55, 0.4]
    unreal = unreal_profile(d, albedo)
    # Christensen & Burley's perpendicular fit typed in again, s = 1.85 - A + 7 |A - 0.8|^3,
    # with Unreal's 0.6 between its mean free path and d (Dmfp2MfpMagicNumber).
    s = np.array([1.85 - a + 7 * abs(a - 0.8) ** 3 for a in albedo])
    np.testing.assert_allclose(np.asarray(unreal["MeanFreePathColor"]) * unreal["MeanFreePathDistance"],
                               0.6 * d * s / 10.0, rtol=1e-14)  # cm
    np.testing.assert_allclose(unreal_distances(unreal), d, rtol=1e-14)
    assert perpendicular_scaling(0.8) == pytest.approx(1.05)


def test_export_names_what_the_pair_cannot_determine():
    with jax.enable_x64(True):
        p = burley_params()
    hdrp = engine_profile(p, "hdrp")
    assert set(hdrp["undetermined"]) >= {"worldScale", "indexOfRefraction"}
    np.testing.assert_allclose(hdrp_distances(hdrp["fields"]), D, rtol=1e-12)
    given = engine_profile(p, "unreal", albedo=[0.9, 0.5, 0.4], world_scale=0.1, mm_per_unit=10.0)
    assert "SurfaceAlbedo" not in given["undetermined"] and "WorldUnitScale" not in given["undetermined"]
    np.testing.assert_allclose(unreal_distances(given["fields"]), 10.0 * D, rtol=1e-12)
    assumed = engine_profile(p, "unreal")
    assert "SurfaceAlbedo" in assumed["undetermined"]


def test_cli_export_writes_the_engine_assets(tmp_path, capsys):
    path = tmp_path / "params.json"
    invsss.write_params(path, {"sss_level": 800.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0, 1.0, 1.0],
                               "variances": (D**2).tolist(), "model": "burley"})
    assert main(["export", str(path), "--format", "hdrp"]) == 0
    hdrp = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(hdrp_distances(hdrp["fields"]), D, rtol=1e-12)
    assert main(["export", str(path), "--format", "unreal", "--albedo", "0.9/0.5/0.4",
                 "--out", str(tmp_path / "unreal.json")]) == 0
    unreal = json.loads((tmp_path / "unreal.json").read_text())
    np.testing.assert_allclose(unreal_distances(unreal["fields"]), D, rtol=1e-12)
    capsys.readouterr()
    sog = tmp_path / "sog.json"
    invsss.write_params(sog, {"sss_level": 800.0, "correction": 0.0, "maxdd": 1.0, "weights": [1.0],
                              "variances": [1.0], "model": "sog"})
    assert main(["export", str(sog), "--format", "hdrp"]) == 2
    assert "hdrp takes a burley fit" in capsys.readouterr().err
