"""The ``fill`` light term (docs/model.md, section 8): the key light's reflectance law
applied with the same albedo to the other lights' part of the source ``S - K``, with
their direction ``fill_light`` and a strength of its own. JAX against the definition
written out in NumPy and against the PyTorch twin, gradients against finite
differences, its identity, the exported shader factor, and the estimator recovering
the strength (and finding none where the other lights are Lambertian)."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import invsss
from invsss.estimator.options import check_light_terms
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_law, reflectance_law
from invsss.validation import InvalidInputError

from _lit_scenes import FIX, PROFILE, dome_with_two_lights, lit_target
from test_reflectance_law import PARAMS, _reference_source, _scene, _unit, hlsl_law_factor


@pytest.fixture(autouse=True)
def _float64():
    with jax.enable_x64(True):
        yield


def _fill_scene(seed=0):
    source, key, depth, mask, normal, light = _scene(seed)
    rng = np.random.default_rng(seed + 100)
    fill_light = rng.normal(size=light.shape)
    fill_light[..., 2] = np.abs(fill_light[..., 2]) + 0.2
    return source, key, depth, mask, normal, light, _unit(fill_light)


def _expected(source, key, mask, normal, light, fill_light, albedo, strength, fill):
    """S + m a K (g(n, l) - 1) + m b (S - K) (g(n, l_f) - 1), from the NumPy reference of the law."""
    keyed = _reference_source(source, key, mask, normal, light, albedo, strength)
    # _reference_source adds m s P (g - 1) for a part P: here P = S - K, s = b.
    return keyed + _reference_source(np.zeros_like(source), source - key, mask, normal, fill_light, albedo, fill)


@pytest.mark.parametrize("albedo", [0.9, [0.95, 0.8, 0.6]])
def test_the_fill_is_the_law_on_the_other_lights(albedo):
    source, key, _, mask, normal, light, fill_light = _fill_scene()
    buffers = LightBuffers(normal, light, key, fill_light)
    out = np.asarray(apply_law(source, mask, albedo, buffers, 0.8, 0.6))
    expected = _expected(source, key, mask, normal, light, fill_light, albedo, 0.8, 0.6)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-13)
    # The fill changes the image beyond the key light's law (else the test would
    # pass for a fill that did nothing).
    key_only = np.asarray(apply_law(source, mask, albedo, buffers, 0.8))
    assert np.abs(out - key_only).max() > 0.02
    # Off the mask nothing changes.
    np.testing.assert_array_equal(out[:2], source[:2])


@pytest.mark.slow
def test_render_applies_the_fill_before_the_blur():
    source, key, depth, mask, normal, light, fill_light = _fill_scene(1)
    buffers = LightBuffers(normal, light, key, fill_light)
    terms = LightTerms(law=[0.95, 0.8, 0.6], law_strength=0.7, fill=1.2)
    out = invsss.render(source, depth, mask, PARAMS, light_terms=terms, light_buffers=buffers)
    lit = _expected(source, key, mask, normal, light, fill_light, [0.95, 0.8, 0.6], 0.7, 1.2)
    np.testing.assert_allclose(np.asarray(out), np.asarray(invsss.render(lit, depth, mask, PARAMS)),
                               rtol=1e-12, atol=1e-13)


def test_fill_zero_is_the_identity_and_the_fill_needs_the_law_and_its_buffer():
    source, key, depth, mask, normal, light, fill_light = _fill_scene(2)
    with_buffer = LightBuffers(normal, light, key, fill_light)
    assert LightTerms(law=0.9, fill=0.0).used == ("law",)
    assert LightTerms(law=0.9, law_strength=0.0, fill=0.5).used == ("fill",)
    np.testing.assert_array_equal(np.asarray(apply_law(source, mask, 0.9, with_buffer, 0.8, 0.0)),
                                  np.asarray(apply_law(source, mask, 0.9, LightBuffers(normal, light, key), 0.8)))
    # The fill has no albedo of its own.
    with pytest.raises(InvalidInputError, match="fill: the law on the other lights uses the law's albedo"):
        LightTerms(fill=0.5).check()
    with pytest.raises(InvalidInputError, match="'fill' applies the law's albedo"):
        check_light_terms("shift,fill")
    assert check_light_terms("law,fill=0.5") == (("law", "fill"), {"fill": 0.5})
    # Without its buffer: one line naming it.
    with pytest.raises(InvalidInputError, match="fill_light: the 'fill' term needs this buffer"):
        invsss.render(source, depth, mask, PARAMS, light_terms=LightTerms(law=0.9, fill=1.0),
                      light_buffers=LightBuffers(normal, light, key))
    # Checked as the other vectors are.
    with pytest.raises(InvalidInputError, match="fill_light: expected unit vectors"):
        invsss.render(source, depth, mask, PARAMS, light_terms=LightTerms(law=0.9, fill=1.0),
                      light_buffers=LightBuffers(normal, light, key, 2.0 * fill_light))


@pytest.mark.slow
def test_gradients_match_finite_differences():
    source, key, depth, mask, normal, light, fill_light = _fill_scene(3)
    buffers = LightBuffers(*(jnp.asarray(x) for x in (normal, light, key, fill_light)))
    weights = jnp.asarray(np.random.default_rng(3).normal(size=source.shape))

    def f(x):
        terms = LightTerms(law=x[:3], law_strength=0.9, fill=x[3])
        return jnp.sum(weights * invsss.render(source, depth, mask, PARAMS, light_terms=terms, light_buffers=buffers))

    x0 = jnp.asarray([0.93, 0.8, 0.55, 0.7])
    grad = np.asarray(jax.grad(f)(x0))
    for i in range(4):
        e = np.zeros(4)
        e[i] = 1e-6
        fd = (float(f(x0 + e)) - float(f(x0 - e))) / 2e-6
        assert grad[i] == pytest.approx(fd, rel=1e-6)
    assert abs(grad[3]) > 1e-3


def test_the_pytorch_twin_matches():
    torch = pytest.importorskip("torch")
    import invsss.torch as itorch

    source, key, _, mask, normal, light, fill_light = _fill_scene(4)
    w = [0.93, 0.8, 0.55]
    out_jax = apply_law(source, mask, w, LightBuffers(normal, light, key, fill_light), 0.8, 0.6)
    t = lambda a: torch.as_tensor(np.array(a), dtype=torch.float64)  # noqa: E731
    out_torch = itorch.apply_law(t(source), t(mask), t(w), t(normal), t(light), t(key), 0.8, t(fill_light), 0.6)
    np.testing.assert_allclose(out_torch.numpy(), np.asarray(out_jax), rtol=1e-13, atol=1e-14)


def test_the_exported_fill_factor_is_the_model():
    _, _, _, _, normal, _, fill_light = _fill_scene(5)
    albedo = [0.93, 0.8, 0.55]
    constants = invsss.shader_constants(PARAMS, light_terms={"law": albedo, "law_strength": 0.7, "fill": 0.4})
    assert constants["lawFillStrength"] == 0.4 and constants["lawStrength"] == 0.7
    hlsl = invsss.to_hlsl(constants, prefix="sss_")
    assert "float3 invsssOtherLightLaw(float3 normal, float3 toLight)" in hlsl
    assert "float3 invsssKeyLightLaw(float3 normal, float3 toLight)" in hlsl
    # Without the fill neither the constant nor the function is written.
    plain = invsss.shader_constants(PARAMS, light_terms={"law": albedo, "law_strength": 0.7})
    assert "lawFillStrength" not in plain and "invsssOtherLightLaw" not in invsss.to_hlsl(plain)
    # The same through a LightTerms.
    assert invsss.shader_constants(PARAMS, light_terms=LightTerms(law=albedo, fill=0.4))["lawFillStrength"] == 0.4

    factor = hlsl_law_factor(hlsl, "invsssOtherLightLaw", constants)
    expected = 1.0 + 0.4 * (np.asarray(reflectance_law(jnp.asarray(normal), jnp.asarray(fill_light),
                                                       jnp.asarray(albedo))) - 1.0)
    for r, c in [(3, 4), (5, 9), (11, 14)]:
        np.testing.assert_allclose(factor(normal[r, c], fill_light[r, c]), expected[r, c], rtol=1e-12)


# ------------------------------------------------------------------ estimator


@pytest.mark.slow
def test_fit_recovers_the_fill_and_gains_over_the_law_alone():
    source, depth, mask, buffers = dome_with_two_lights()
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7], fill=1.0))
    kw = dict(profile=PROFILE, fix=FIX, n_starts=2, light_buffers=buffers)
    fit = invsss.fit_pair(source, target, depth, mask, light_terms="law,fill", **kw)
    assert fit.converged
    terms = fit.light_terms
    assert terms["stderr"]["fill"] is not None and abs(terms["fill"] - 1.0) < 4 * terms["stderr"]["fill"]
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.02)
    # Measured, not assumed: the fill's share of the fit, and the law alone fits worse.
    assert fit.psnr - terms["psnr_without"]["fill"] > 1.0
    key_only = invsss.fit_pair(source, target, depth, mask, light_terms="law", **kw)
    assert key_only.psnr < fit.psnr - 1.0
    # The fitted values render as fitted.
    assert float(fit.light_terms_params().fill) == pytest.approx(terms["fill"])
    assert not any("a gain that neither" in w for w in fit.warnings)


@pytest.mark.slow
def test_other_lights_darker_than_any_medium_are_warned_about():
    # The target's other lights lose light where every medium reflects more than
    # Lambert's law (a fill strength of -1.5): the fit finds that and says so.
    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7], fill=-1.5))
    fit = invsss.fit_pair(source, target, depth, mask, light_terms="law,fill", profile=PROFILE, fix=FIX,
                          n_starts=1, light_buffers=buffers)
    assert fit.light_terms["fill"] < -1.0
    assert any(w.startswith("light_terms.fill: at ") and "a gain that neither" in w for w in fit.warnings)


@pytest.mark.slow
def test_lambertian_other_lights_fit_as_the_law_alone():
    # The target's other lights are Lambertian (fill 0): the fill must find nothing,
    # and the fit with it must not end below the fit without it.
    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7]))
    kw = dict(profile=PROFILE, fix=FIX, n_starts=1, light_buffers=buffers)
    with_fill = invsss.fit_pair(source, target, depth, mask, light_terms="law,fill", **kw)
    key_only = invsss.fit_pair(source, target, depth, mask, light_terms="law", **kw)
    terms = with_fill.light_terms
    assert abs(terms["fill"]) < 4 * terms["stderr"]["fill"]
    assert with_fill.psnr > key_only.psnr - 0.05
    assert any("light_terms.fill: adds" in w for w in with_fill.warnings)


@pytest.mark.slow
def test_cli_fit_render_and_export_with_the_fill_light_buffer(tmp_path, capsys):
    from _pair_files import pair_args, write_pair
    from invsss.cli import main

    source, depth, mask, buffers = dome_with_two_lights(32)
    target = lit_target(source, depth, mask, buffers, LightTerms(law=[0.9, 0.8, 0.7], fill=1.0), noise=0.0)
    paths = write_pair(tmp_path, "lit", (source, target, depth, mask))
    files = {}
    for name in ("normal", "light", "key", "fill_light"):
        files[name] = str(tmp_path / f"{name}.exr")
        invsss.write_image(files[name], np.asarray(getattr(buffers, name), np.float32))
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    common = [*pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1", "--starts", "1",
              "--normal", files["normal"], "--light", files["light"], "--key", files["key"]]
    assert main(["fit", *common, "--fill-light", files["fill_light"], "--light-terms", "law,fill",
                 "--out", str(tmp_path / "fit")]) == 0
    stored = json.loads((tmp_path / "fit" / "params.json").read_text())["light_terms"]
    assert abs(stored["fill"] - 1.0) < 0.1 and "fill" in stored["psnr_without"]
    capsys.readouterr()
    # The fill without its buffer: one line naming it, nothing written.
    assert main(["fit", *common, "--light-terms", "law,fill", "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "invsss: error: --fill-light: the 'fill' term needs this buffer" in err and "Traceback" not in err

    params_path = str(tmp_path / "fit" / "params.json")
    scene = ["--image", str(paths["source"]), "--depth", str(paths["depth"]), "--mask", str(paths["mask"]),
             "--params", params_path, "--normal", files["normal"], "--light", files["light"], "--key", files["key"]]
    assert main(["render", *scene, "--out", str(tmp_path / "bad.exr")]) != 0
    err = capsys.readouterr().err
    assert "holds the 'fill' light term, which needs --fill-light" in err and "Traceback" not in err
    assert main(["render", *scene, "--fill-light", files["fill_light"], "--out", str(tmp_path / "lit.exr")]) == 0
    fitted, _ = invsss.read_params(params_path)
    read = {name: invsss.read_image(path) for name, path in files.items()}
    terms = LightTerms(law=stored["law"], law_strength=stored["law_strength"], fill=stored["fill"])
    expected = np.asarray(invsss.render(invsss.read_image(paths["source"]), depth, mask, fitted, light_terms=terms,
                                        light_buffers=LightBuffers(read["normal"], read["light"], read["key"],
                                                                   read["fill_light"])))
    np.testing.assert_allclose(invsss.read_image(tmp_path / "lit.exr"), expected, atol=1e-5)
    capsys.readouterr()
    assert main(["export", params_path, "--format", "hlsl"]) == 0
    assert "invsssOtherLightLaw" in capsys.readouterr().out


def test_a_sweep_reads_fill_light_only_for_trials_with_the_fill(tmp_path):
    import invsss.experiments as ex
    from _pair_files import light_sweep_text, write_pair_folder

    source, depth, mask, buffers = dome_with_two_lights(16)
    folder = tmp_path / "data" / "dome"
    write_pair_folder(folder, (source, source, depth, mask), buffers, roles=("normal", "light", "key"))
    path = tmp_path / "fill.toml"
    path.write_text(light_sweep_text('["law", "law,fill"]'))
    # Without fill_light.exr the trial with the fill is refused before anything runs.
    with pytest.raises(InvalidInputError, match=r"light term 'fill' needs fill_light\.exr in pair 'dome'"):
        ex.load(path)
    law_only = tmp_path / "law.toml"
    law_only.write_text(light_sweep_text('["law"]'))
    id_without = ex.load(law_only).trials[0].id
    invsss.write_image(folder / "fill_light.exr", np.asarray(buffers.fill_light, np.float32))
    law, fill = ex.load(path).trials
    # A folder that gained fill_light.exr keeps the ids of its trials without the fill.
    assert law.id == id_without and "fill_light" not in law.config["pairs"][0]
    assert "fill_light" in fill.config["pairs"][0] and "fill_light" in fill.buffer_roles
    # A pair given file by file names its fill_light too.
    files = tmp_path / "files.toml"
    names = {role: f"data/dome/{role}.{'png' if role == 'mask' else 'exr'}"
             for role in ("source", "target", "depth", "mask", "normal", "light", "key", "fill_light")}
    files.write_text(light_sweep_text('["law,fill"]').replace(
        '[data]\npairs = ["data/*/"]\n',
        "[data]\n[[data.files]]\nname = \"dome\"\n" + "".join(f'{k} = "{v}"\n' for k, v in names.items())))
    (trial,) = ex.load(files).trials
    assert trial.config["pairs"][0]["fill_light"] == names["fill_light"]
