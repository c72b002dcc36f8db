"""The ``law`` light term (docs/model.md, section 8): the key light's part of the source
under Chandrasekhar's reflectance law. JAX against a NumPy reference of the
definition, against the PyTorch twin and the exported HLSL, gradients against finite
differences, and the estimator recovering the albedos from model-made pairs."""

from __future__ import annotations

import json
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_law, reflectance_law

from _lit_scenes import FIX, PROFILE, dome_with_two_lights, lit_target


@pytest.fixture(autouse=True)
def _float64():
    with jax.enable_x64(True):
        yield


H, W = 12, 15
PARAMS = invsss.SSSParams(800.0, 300.0, 0.5, [0.5, 0.5], [0.3, 1.5])


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _scene(seed=0):
    """Random source and key light's part, normals and light directions, some of
    them facing away from the light (``n . l < 0``: the key light does not reach)."""
    rng = np.random.default_rng(seed)
    key = rng.uniform(0.0, 0.6, (H, W, 3))
    source = key + rng.uniform(0.1, 0.4, (H, W, 3))
    depth = 500.0 + rng.uniform(0.0, 20.0, (H, W))
    mask = np.ones((H, W))
    mask[:2] = 0.0
    mask[2, :4] = 0.5
    normal = rng.normal(size=(H, W, 3))
    normal[..., 2] = np.abs(normal[..., 2]) + 0.3
    light = rng.normal(size=(H, W, 3))
    light[..., 2] = np.abs(light[..., 2]) + 0.2
    return source, key, depth, mask, _unit(normal), _unit(light)


def _reference_source(source, key, mask, normal, light, albedo, strength=1.0):
    """docs/model.md, section 8, written out: S + m a K (g - 1), with
    g = 1 + t (f_w(mu, mu0) / f_w(1, 1) - 1) and t = clip(min(n_z, n . l) / 0.1, 0, 1)."""
    w = np.broadcast_to(np.asarray(albedo, np.float64), (source.shape[-1],))
    out = np.empty_like(source)
    n_dot_l = np.einsum("hwk,hwk->hw", normal, light)
    trust = np.clip(np.minimum(normal[..., 2], n_dot_l) / 0.1, 0.0, 1.0)
    for c in range(source.shape[-1]):
        root = np.sqrt(1.0 - w[c])

        def h(x):
            return (1.0 + 2.0 * x) / (1.0 + 2.0 * x * root)

        mu = np.clip(normal[..., 2], 0.0, 1.0)
        mu0 = np.clip(n_dot_l, 0.0, 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            law = np.where(trust > 0, h(mu) * h(mu0) / (mu + mu0), 0.0)
        head_on = h(1.0) * h(1.0) / 2.0
        gain = 1.0 + trust * (law / head_on - 1.0)
        out[..., c] = source[..., c] + strength * mask * key[..., c] * (gain - 1.0)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("albedo", [0.9, [0.95, 0.8, 0.6]])
def test_render_applies_the_law_to_the_source_before_the_blur(albedo):
    source, key, depth, mask, normal, light = _scene()
    buffers = LightBuffers(normal=normal, light=light, key=key)
    out = invsss.render(source, depth, mask, PARAMS, light_terms=LightTerms(law=albedo), light_buffers=buffers)
    expected = invsss.render(_reference_source(source, key, mask, normal, light, albedo), depth, mask, PARAMS)
    np.testing.assert_allclose(np.asarray(out), np.asarray(expected), rtol=1e-12, atol=1e-13)
    # The law changes the image: the test would pass for no term at all otherwise.
    assert np.abs(np.asarray(out) - np.asarray(invsss.render(source, depth, mask, PARAMS))).max() > 0.01


def test_the_law_leaves_head_on_light_and_the_other_lights_alone():
    source, key, depth, mask, normal, light = _scene(1)
    facing = np.zeros_like(normal)
    facing[..., 2] = 1.0
    # Light arriving and leaving along the normal: the law's gain is 1.
    same = apply_law(source, mask, 0.7, LightBuffers(facing, facing, key))
    np.testing.assert_allclose(np.asarray(same), source, atol=1e-14)
    # No key light: nothing for the law to act on.
    none = apply_law(source, mask, 0.7, LightBuffers(normal, light, np.zeros_like(key)))
    np.testing.assert_array_equal(np.asarray(none), source)
    # Off the mask the source is kept.
    changed = np.asarray(apply_law(source, mask, 0.7, LightBuffers(normal, light, key)))
    np.testing.assert_array_equal(changed[:2], source[:2])
    assert np.abs(changed[3:] - source[3:]).max() > 0.05


@pytest.mark.slow
def test_the_law_has_the_known_limits_and_order_in_albedo():
    # Low albedo: single scattering, the Lommel-Seeliger law 1 / (mu + mu0);
    # albedo near 1: H(x) -> 1 + 2x, the conservative medium. In between, the lower
    # the albedo, the more light comes back at oblique incidence relative to
    # head-on (less of it is absorbed on the way out from near the surface).
    rng = np.random.default_rng(9)
    normal = _unit(rng.normal(size=(4, 5, 3)) + [0.0, 0.0, 2.0])
    light = _unit(rng.normal(size=(4, 5, 3)) + [0.0, 0.0, 1.0])
    mu = np.clip(normal[..., 2], 0.0, 1.0)
    mu0 = np.clip(np.einsum("hwk,hwk->hw", normal, light), 0.0, 1.0)
    # The law is trusted where both cosines reach 0.1, faded to Lambert (1) below.
    trust = np.clip(np.minimum(normal[..., 2], np.einsum("hwk,hwk->hw", normal, light)) / 0.1, 0.0, 1.0)
    assert 0 < np.mean(trust == 1.0) < 1  # both kinds of pixel are tested

    def gain(w):
        return np.asarray(reflectance_law(jnp.asarray(normal), jnp.asarray(light), w))[..., 0]

    def faded(law):
        return 1.0 + trust * (np.where(trust > 0, law, 1.0) - 1.0)

    with np.errstate(divide="ignore", invalid="ignore"):
        np.testing.assert_allclose(gain(1e-12), faded(2.0 / (mu + mu0)), rtol=1e-9)
        # sqrt(1 - w) is floored at 1e-6, which moves H by up to about 2e-6 relative.
        np.testing.assert_allclose(gain(1.0 - 1e-12), faded((1 + 2 * mu) * (1 + 2 * mu0) / (mu + mu0) / 4.5),
                                   rtol=1e-5)
    facing = np.zeros((1, 3, 3))
    facing[..., 2] = 1.0
    oblique = _unit(np.array([[[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.95, 0.0, 0.312]]]))
    ratios = {w: np.asarray(reflectance_law(jnp.asarray(facing), jnp.asarray(oblique), w))[0, :, 0]
              for w in (0.5, 0.9, 0.99)}
    assert all(r[0] == pytest.approx(1.0) for r in ratios.values())
    assert ratios[0.5][2] > ratios[0.9][2] > ratios[0.99][2]
    assert ratios[0.5][1] > ratios[0.9][1] > ratios[0.99][1]


@pytest.mark.slow
def test_gradients_match_finite_differences():
    source, key, depth, mask, normal, light = _scene(2)
    buffers = LightBuffers(normal=jnp.asarray(normal), light=jnp.asarray(light), key=jnp.asarray(key))
    weights = jnp.asarray(np.random.default_rng(3).normal(size=(H, W, 3)))

    def f(w):
        return jnp.sum(weights * invsss.render(source, depth, mask, PARAMS, light_terms=LightTerms(law=w),
                                               light_buffers=buffers))

    w0 = jnp.asarray([0.93, 0.8, 0.55])
    grad = np.asarray(jax.grad(f)(w0))
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1e-6
        fd = (float(f(w0 + e)) - float(f(w0 - e))) / 2e-6
        assert grad[i] == pytest.approx(fd, rel=1e-6)
    assert np.all(np.abs(grad) > 1e-3)


def test_the_law_composes_with_jit_and_vmap():
    source, key, _, mask, normal, light = _scene(4)
    albedos = jnp.asarray([[0.9, 0.8, 0.7], [0.5, 0.5, 0.5]])
    batched = jax.jit(jax.vmap(lambda w: apply_law(source, mask, w, LightBuffers(normal, light, key))))(albedos)
    for k in range(2):
        one = apply_law(source, mask, albedos[k], LightBuffers(normal, light, key))
        np.testing.assert_allclose(np.asarray(batched[k]), np.asarray(one), atol=1e-14)


class TestBadInput:
    def setup_method(self):
        self.source, self.key, self.depth, self.mask, self.normal, self.light = _scene()

    def _render(self, terms, buffers):
        return invsss.render(self.source, self.depth, self.mask, PARAMS, light_terms=terms, light_buffers=buffers)

    def test_missing_key_is_named(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: the 'law' term needs this buffer"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light))

    def test_key_of_another_size_or_channel_count(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: expected shape \(12, 15, 3\)"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light, self.key[..., :1]))
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: expected shape"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light, self.key[:5]))

    def test_nan_in_the_key(self):
        key = self.key.copy()
        key[4, 4, 1] = np.nan
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.key: NaN"):
            self._render(LightTerms(law=0.9), LightBuffers(self.normal, self.light, key))

    @pytest.mark.parametrize("albedo", [1.0, 0.0, -0.2, [0.9, 1.3, 0.5], float("nan")])
    def test_albedo_outside_zero_to_one(self, albedo):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\.law: expected an albedo in \(0, 1\)"):
            self._render(LightTerms(law=albedo), LightBuffers(self.normal, self.light, self.key))

    def test_one_albedo_per_channel(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\.law: expected one albedo or one per image"):
            self._render(LightTerms(law=[0.9, 0.8]), LightBuffers(self.normal, self.light, self.key))

    @pytest.mark.parametrize("terms, message", [
        ("law=1.2", r"light_terms\['law'\]: expected an albedo in \(0, 1\) or one per channel"),
        ({"law": "0.9/x"}, r"light_terms\['law'\]: expected an albedo"),
    ])
    def test_held_albedos_are_checked(self, terms, message):
        from invsss.estimator import FitOptions

        with pytest.raises(invsss.InvalidInputError, match=message):
            FitOptions(light_terms=terms)

    def test_a_fit_names_the_missing_key(self):
        with pytest.raises(invsss.InvalidInputError, match=r"^light_buffers\.key: the 'law' term needs this buffer"):
            invsss.fit_pair(self.source, self.source, self.depth, self.mask, light_terms="law",
                            light_buffers=LightBuffers(self.normal, self.light))

    @pytest.mark.slow
    def test_a_held_albedo_count_must_match_the_source(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\['law'\]: expected one albedo or one per "
                                                           r"source channel \(3\), got 2"):
            invsss.fit_pair(self.source, self.source, self.depth, self.mask, light_terms={"law": [0.9, 0.8]},
                            light_buffers=LightBuffers(self.normal, self.light, self.key))


class TestTorchTwin:
    torch = pytest.importorskip("torch")

    def test_values_and_gradients_agree(self):
        torch = self.torch
        import invsss.torch as itorch

        source, key, _, mask, normal, light = _scene(5)
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

        source, key, _, mask, normal, light = _scene(7)
        t = lambda a: torch.as_tensor(np.array(a), dtype=torch.float64)  # noqa: E731

        def f(w):
            return itorch.apply_law(t(source), t(mask), w, t(normal), t(light), t(key))

        w = torch.tensor([0.91, 0.6, 0.3], dtype=torch.float64, requires_grad=True)
        assert torch.autograd.gradcheck(f, (w,))


# ------------------------------------------------------------------ export


class _Vector(np.ndarray):
    """A float3 with HLSL's ``.x``, ``.y``, ``.z``."""

    x = property(lambda self: float(self[0]))
    y = property(lambda self: float(self[1]))
    z = property(lambda self: float(self[2]))


def _hlsl_function_as_python(text: str, name: str):
    """The body of an HLSL function of :data:`invsss.io.export.LAW_HLSL`, run as NumPy.

    The snippet is plain arithmetic on float and float3 values; a handful of
    substitutions make each statement Python, so the test runs the shader's own
    text rather than a copy of its formula.
    """
    body = text[text.index(name):]
    body = body[body.index("{") + 1: body.index("\n}")]
    lines = []
    for statement in body.strip().split(";"):
        statement = " ".join(statement.split())
        if not statement:
            continue
        statement = re.sub(r"^(float3|float) ", "", statement)
        statement = statement.replace("return ", "result = ")
        lines.append(statement)
    return "\n".join(lines)


def hlsl_law_factor(hlsl: str, name: str, constants: dict, prefix: str = "sss_"):
    """The law factor ``name`` of a constants text (``invsssKeyLightLaw`` or
    ``invsssOtherLightLaw``) as a Python function of one pixel's normal and light
    direction, run from the shader's own text with the constants' values."""
    hapke = _hlsl_function_as_python(hlsl, "float3 invsssHapkeH")
    factor = _hlsl_function_as_python(hlsl, f"float3 {name}")
    helpers = {
        "np": np,
        "sqrt": np.sqrt,
        "max": np.maximum,
        "clamp": np.clip,
        "saturate": lambda x: np.clip(x, 0.0, 1.0),
        "dot": lambda a, b: float(np.dot(a, b)),
        "float3": lambda *v: np.array(v, np.float64),
        "min": np.minimum,
        **{prefix + key: value for key, value in constants.items() if key.startswith("law")},
    }

    def invsssHapkeH(x, w):  # noqa: N802 - the shader's name
        scope = {**helpers, "x": x, "w": w}
        exec(hapke, scope)
        return scope["result"]

    helpers["invsssHapkeH"] = invsssHapkeH

    def run(normal, to_light):
        scope = {**helpers, "normal": np.array(normal, np.float64).view(_Vector),
                 "toLight": np.array(to_light, np.float64).view(_Vector)}
        exec(factor, scope)
        return scope["result"]

    return run


@pytest.mark.slow
def test_the_exported_law_is_the_model():
    source, key, _, mask, normal, light = _scene(8)
    albedo = [0.93, 0.8, 0.55]
    constants = invsss.shader_constants(PARAMS, light_terms={"law": albedo, "law_strength": 0.7, "shift": 1.1})
    assert constants["lawAlbedo"] == albedo and constants["lightShift"] == 1.1
    assert constants["lawStrength"] == 0.7
    hlsl = invsss.to_hlsl(constants, prefix="sss_")
    assert "static const float sss_lawAlbedo[3] = { 0.93, 0.8, 0.55 };" in hlsl
    assert "float3 invsssKeyLightLaw(float3 normal, float3 toLight)" in hlsl

    law = hlsl_law_factor(hlsl, "invsssKeyLightLaw", constants)
    # The key light's factor at strength a: 1 + a (g - 1).
    expected = 1.0 + 0.7 * (np.asarray(reflectance_law(jnp.asarray(normal), jnp.asarray(light),
                                                       jnp.asarray(albedo))) - 1.0)
    for r, c in [(3, 4), (5, 9), (11, 14), (7, 0)]:
        n, l_ = normal[r, c].copy(), light[r, c].copy()
        if r == 7:
            l_ = -n  # the key light behind the surface: mu0 = 0
        wanted = expected[r, c] if r != 7 else 1.0 + 0.7 * (np.asarray(
            reflectance_law(jnp.asarray(n[None, None]), jnp.asarray(l_[None, None]), jnp.asarray(albedo)))[0, 0] - 1.0)
        np.testing.assert_allclose(law(n, l_), wanted, rtol=1e-12)


def test_only_the_law_exports_no_after_blur_constants():
    constants = invsss.shader_constants(PARAMS, light_terms=LightTerms(law=0.9))
    assert "lightShift" not in constants and len(constants["lawAlbedo"]) == 3
    assert constants["lawAlbedo"][0] == constants["lawAlbedo"][2] == pytest.approx(0.9)
    hlsl = invsss.to_hlsl(constants)
    assert "invsssKeyLightLaw" in hlsl and "invsssLightTerms" not in hlsl


# ------------------------------------------------------------------ estimator


@pytest.mark.slow
def test_fit_recovers_an_albedo_per_channel_and_the_blur():
    source, depth, mask, buffers = dome_with_two_lights()
    truth = [0.95, 0.85, 0.7]
    target = lit_target(source, depth, mask, buffers, LightTerms(law=truth))
    fit = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2,
                          light_terms="law", light_buffers=buffers)
    assert fit.converged
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.02)
    fitted, errors = fit.light_terms["law"], fit.light_terms["stderr"]["law"]
    assert len(fitted) == len(errors) == 3 and fit.light_terms["fixed"] == []
    # Honest errors: each albedo within 4 of its standard errors of the truth.
    for w, err, true in zip(fitted, errors, truth):
        assert err is not None and 0 < err < 0.02 and abs(w - true) < 4 * err
    # The fitted values render as fitted: light_terms_params carries the albedos.
    np.testing.assert_allclose(np.asarray(fit.light_terms_params().law), fitted, rtol=1e-6)
    # Without the law the same data give a biased blur and a worse fit.
    plain = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2)
    assert plain.psnr < fit.psnr - 5.0
    from invsss.cli.report import _parameter_lines

    assert "law albedo 0.9" in "\n".join(_parameter_lines(fit))


@pytest.mark.slow
def test_a_held_albedo_is_kept_and_a_grey_target_fits_one_per_source_channel():
    source, depth, mask, buffers = dome_with_two_lights(32)
    truth = [0.95, 0.85, 0.7]
    target = lit_target(source, depth, mask, buffers, LightTerms(law=truth))
    held = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1,
                           light_terms={"law": truth}, light_buffers=buffers)
    assert held.light_terms["law"] == pytest.approx(truth) and held.light_terms["fixed"] == ["law"]
    assert held.light_terms["stderr"]["law"] is None
    assert float(held.params.sss_level) == pytest.approx(600.0, rel=0.02)
    # A grey (NIR-like) photograph of an RGB render: the law acts per source
    # channel, before the grey mix, so a grey target still gets three albedos.
    grey = target @ np.array([0.3, 0.5, 0.2])
    mixed = invsss.fit_pair(source, grey, depth, mask, profile=PROFILE, fix=FIX, n_starts=1,
                            light_terms="law", light_buffers=buffers)
    assert len(mixed.light_terms["law"]) == 3 and mixed.converged


@pytest.mark.slow
def test_cli_fit_and_render_with_the_key_buffer(tmp_path, capsys):
    from _pair_files import pair_args, write_pair
    from invsss.cli import main

    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.95, 0.85, 0.7]), noise=0.0)
    paths = write_pair(tmp_path, "lit", (source, target, depth, mask))
    files = {}
    for name in ("normal", "light", "key"):
        files[name] = str(tmp_path / f"{name}.exr")
        invsss.write_image(files[name], np.asarray(getattr(buffers, name), np.float32))
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    common = [*pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1", "--starts", "1",
              "--normal", files["normal"], "--light", files["light"]]
    assert main(["fit", *common, "--key", files["key"], "--light-terms", "law", "--out", str(tmp_path / "fit")]) == 0
    stored = json.loads((tmp_path / "fit" / "params.json").read_text())["light_terms"]
    # The strength trades against the albedos' common level (docs/model.md, section
    # 8): the truth lies within 4 of their standard errors.
    assert len(stored["stderr"]["law"]) == 3
    for w, err, true in zip(stored["law"], stored["stderr"]["law"], [0.95, 0.85, 0.7]):
        assert abs(w - true) < 4 * err
    assert abs(stored["law_strength"] - 1.0) < 0.1
    capsys.readouterr()
    # The law without --key: one line naming the buffer, nothing written.
    assert main(["fit", *common, "--light-terms", "law", "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "invsss: error: --key: the 'law' term needs this buffer" in err and "Traceback" not in err
    # A key of another channel count: one line naming the file.
    invsss.write_image(tmp_path / "grey_key.exr", np.asarray(buffers.key[..., 0], np.float32))
    assert main(["fit", *common, "--key", str(tmp_path / "grey_key.exr"), "--light-terms", "law",
                 "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "grey_key.exr: expected an image of the source's size and channels" in err and "Traceback" not in err

    # invsss render applies the fitted law: the library's render with the stored albedos.
    params_path = str(tmp_path / "fit" / "params.json")
    scene = ["--image", str(paths["source"]), "--depth", str(paths["depth"]), "--mask", str(paths["mask"]),
             "--params", params_path, "--normal", files["normal"], "--light", files["light"]]
    assert main(["render", *scene, "--key", files["key"], "--out", str(tmp_path / "lit.exr")]) == 0
    assert "light terms law=0.9" in capsys.readouterr().out
    fitted, _ = invsss.read_params(params_path)
    read = {name: invsss.read_image(path) for name, path in files.items()}
    expected = np.asarray(invsss.render(invsss.read_image(paths["source"]), depth, mask, fitted,
                                        light_terms=LightTerms(law=stored["law"],
                                                               law_strength=stored["law_strength"]),
                                        light_buffers=LightBuffers(read["normal"], read["light"], read["key"])))
    np.testing.assert_allclose(invsss.read_image(tmp_path / "lit.exr"), expected, atol=1e-5)
    assert main(["render", *scene, "--out", str(tmp_path / "bad.exr")]) != 0
    err = capsys.readouterr().err
    assert "holds the 'law' light term, which needs --key" in err and "Traceback" not in err
    # The exported shader carries the albedos.
    assert main(["export", params_path, "--format", "hlsl"]) == 0
    assert "lawAlbedo[3]" in capsys.readouterr().out


@pytest.mark.slow
def test_sweep_reads_the_key_only_for_trials_with_the_law(tmp_path):
    import invsss.experiments as ex
    from _pair_files import light_sweep_text, write_pair_folder

    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.95, 0.85, 0.7]))
    folder = tmp_path / "data" / "dome"
    write_pair_folder(folder, (source, target, depth, mask), buffers)
    text = light_sweep_text('["incidence", "law"]')
    path = tmp_path / "law.toml"
    path.write_text(text)
    # Without key.exr the trial with the law is refused before anything runs.
    with pytest.raises(invsss.InvalidInputError, match=r"light term 'law' needs key\.exr in pair 'dome'"):
        ex.load(path)
    incidence_only = tmp_path / "incidence.toml"
    incidence_only.write_text(text.replace('["incidence", "law"]', '["incidence"]'))
    id_without_key = ex.load(incidence_only).trials[0].id
    invsss.write_image(folder / "key.exr", np.asarray(buffers.key, np.float32))
    experiment = ex.load(path)
    incidence, law = experiment.trials
    # A folder that gained key.exr keeps the ids of its trials without the law.
    assert incidence.id == id_without_key and "key" not in incidence.config["pairs"][0]
    assert "key" in law.config["pairs"][0]
    ex.run(path, tmp_path / "out")
    rows = {r["light_terms"]: r for r in ex.results(tmp_path / "out", frame=False)}
    assert all(r["status"] == "done" for r in rows.values())
    assert len(rows["law"]["stderr.law"]) == 3 and rows["incidence"]["param.law"] is None
    for w, err, true in zip(rows["law"]["param.law"], rows["law"]["stderr.law"], [0.95, 0.85, 0.7]):
        assert abs(w - true) < 4 * err


@pytest.mark.slow
def test_an_aligned_fit_moves_the_key_with_the_source():
    # The photograph is misregistered by a fraction of a pixel; the aligned fit
    # resamples the source onto it, and the key light's part must move with it,
    # or the law would change the wrong pixels.
    source, depth, mask, buffers = dome_with_two_lights(40)
    truth = [0.95, 0.85, 0.7]
    target = lit_target(source, depth, mask, buffers, LightTerms(law=truth), noise=0.0)
    shifted = np.stack([ndimage.shift(target[..., k], (1.4, -0.8), order=5, mode="nearest") for k in range(3)], -1)
    # Two starts: from one, this dome has a second minimum at sss_level 746 (loss 2e-7),
    # with or without the warp.
    fit = invsss.fit_pair(source, shifted, depth, mask, profile=PROFILE, fix=FIX, n_starts=2, robust=None,
                          align="translation", light_terms="law", light_buffers=buffers)
    np.testing.assert_allclose(fit.alignment[0]["shift_px"], (1.4, -0.8), atol=0.1)
    assert fit.light_terms["law"] == pytest.approx(truth, abs=0.02)
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.05)
