"""The light-aware terms (docs/model.md, section 8): JAX against a SciPy reference of
the definition, against the PyTorch twin, and gradients against finite differences."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

import invsss
from invsss.forward.light_terms import LightBuffers, LightTerms, apply_light_terms, shift_image



@pytest.fixture(autouse=True)
def _float64():
    # These tests compare against float64 references; x64 is switched on for each
    # test only, so other tests in the same worker keep JAX's float32 default.
    with jax.enable_x64(True):
        yield

H, W = 12, 15


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _scene(seed=0):
    rng = np.random.default_rng(seed)
    image = rng.uniform(0.2, 1.0, (H, W, 3))
    depth = 500.0 + rng.uniform(0.0, 20.0, (H, W))
    mask = np.ones((H, W))
    mask[:2] = 0.0
    mask[2, :4] = 0.5
    light = rng.normal(size=(H, W, 3))
    light[..., 2] = np.abs(light[..., 2]) + 1.0
    normal = rng.normal(size=(H, W, 3))
    normal[..., 2] = np.abs(normal[..., 2]) + 0.3
    params = invsss.SSSParams(800.0, 300.0, 0.5, [0.5, 0.5], [0.3, 1.5])
    return image, depth, mask, _unit(light), _unit(normal), params


def _reference(blurred, depth, mask, light, normal, params, shift, grazing, incidence=0.0):
    """Section 8 written out with SciPy's bilinear interpolation (clamped coordinates)."""
    ddy, ddx = np.gradient(depth)
    L, c, delta = float(params.sss_level), float(params.correction), float(params.maxdd)
    s_x = L / (depth + c * np.minimum(np.abs(ddx), delta))
    s_y = L / (depth + c * np.minimum(np.abs(ddy), delta))
    dx, dy = shift * s_x * -light[..., 0], shift * s_y * light[..., 1]
    rows, cols = np.meshgrid(np.arange(H, dtype=float), np.arange(W, dtype=float), indexing="ij")
    coords = [np.clip(rows - dy, 0, H - 1), np.clip(cols - dx, 0, W - 1)]
    moved = np.stack([ndimage.map_coordinates(blurred[..., k], coords, order=1) for k in range(3)], -1)
    moved *= (1.0 + grazing * (1.0 - np.clip(normal[..., 2], 0.0, 1.0)))[..., None]
    cos_incidence = np.einsum("hwc,hwc->hw", normal, light)
    moved *= (1.0 + incidence * (1.0 - np.clip(cos_incidence, 0.0, 1.0)))[..., None]
    return blurred + mask[..., None] * (moved - blurred)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("shift, grazing, incidence", [(3.0, 0.3, 0.0), (-1.5, -0.4, 0.5), (0.0, 0.7, -0.3),
                                                        (0.0, 0.0, 0.8)])
def test_render_matches_the_definition(seed, shift, grazing, incidence):
    image, depth, mask, light, normal, params = _scene(seed)
    terms = LightTerms(shift=shift, grazing=grazing, incidence=incidence)
    out = invsss.render(image, depth, mask, params, light_terms=terms,
                        light_buffers=LightBuffers(normal=normal, light=light))
    blurred = np.asarray(invsss.render(image, depth, mask, params))
    expected = _reference(blurred, depth, mask, light, normal, params, shift, grazing, incidence)
    np.testing.assert_allclose(np.asarray(out), expected, rtol=0, atol=1e-12)
    # The terms do something (otherwise the comparison above would prove little);
    # a shift moves content by more than a pixel somewhere.
    assert np.max(np.abs(np.asarray(out) - blurred)) > 0.05


@pytest.mark.slow
def test_shift_moves_an_edge_away_from_the_light():
    # A vertical edge lit from the camera's left (l_x < 0): light travels right,
    # so the edge moves right by kappa * s_x pixels.
    image = np.zeros((6, 20, 1))
    image[:, 10:] = 1.0
    depth = np.full((6, 20), 400.0)
    light = np.zeros((6, 20, 3))
    light[..., 0], light[..., 2] = -0.6, 0.8
    params = invsss.SSSParams(400.0, 0.0, 1.0, [1.0], [1e-8])  # s = 1 px/mm, no blur
    out = invsss.render(image, depth, np.ones((6, 20)), params, light_terms=LightTerms(shift=2.5),
                        light_buffers=LightBuffers(light=light))
    row = np.asarray(out)[3, :, 0]
    # The 0.5 crossing moves from 9.5 to 9.5 + 2.5 * 0.6 = 11.
    crossing = np.interp(0.5, row, np.arange(20.0))
    assert crossing == pytest.approx(11.0, abs=1e-9)


def test_zero_terms_are_the_identity():
    image, depth, mask, light, normal, params = _scene()
    blurred = invsss.render(image, depth, mask, params)
    out = invsss.render(image, depth, mask, params, light_terms=LightTerms(),
                        light_buffers=LightBuffers(normal=normal, light=light))
    np.testing.assert_array_equal(np.asarray(out), np.asarray(blurred))


@pytest.mark.slow
def test_gradients_match_finite_differences():
    image, depth, mask, light, normal, params = _scene()
    blurred = jnp.asarray(invsss.render(image, depth, mask, params))
    buffers = LightBuffers(normal=jnp.asarray(normal), light=jnp.asarray(light))
    weights = jnp.asarray(np.random.default_rng(3).normal(size=(H, W, 3)))

    def f(x):
        p = invsss.SSSParams(x[2], params.correction, params.maxdd, params.weights, params.variances)
        out = apply_light_terms(blurred, jnp.asarray(depth), jnp.asarray(mask), p,
                                LightTerms(shift=x[0], grazing=x[1], incidence=x[3]), buffers)
        return jnp.sum(weights * out)

    # Away from integer sample positions (kinks of linear interpolation).
    x0 = jnp.asarray([1.37, 0.21, 810.0, -0.17])
    grad = np.asarray(jax.grad(f)(x0))
    for i, h in enumerate([1e-6, 1e-6, 1e-3, 1e-6]):
        e = np.zeros(4)
        e[i] = h
        fd = (float(f(x0 + e)) - float(f(x0 - e))) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=1e-5, abs=1e-8)
    assert np.all(np.abs(grad) > 1e-3)


@pytest.mark.slow
def test_shift_image_composes_with_jit_and_vmap():
    rng = np.random.default_rng(5)
    images = jnp.asarray(rng.uniform(size=(4, 7, 9, 2)))
    offset = jnp.asarray(rng.uniform(-1.5, 1.5, size=(7, 9, 2)))
    batched = jax.jit(jax.vmap(shift_image, in_axes=(0, None)))(images, offset)
    for k in range(4):
        np.testing.assert_allclose(np.asarray(batched[k]), np.asarray(shift_image(images[k], offset)), atol=1e-14)


class TestBadInput:
    def setup_method(self):
        self.image, self.depth, self.mask, self.light, self.normal, self.params = _scene()

    def _render(self, terms, buffers):
        return invsss.render(self.image, self.depth, self.mask, self.params, light_terms=terms,
                             light_buffers=buffers)

    def test_missing_buffer_is_named(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.light: the 'shift' term needs"):
            self._render(LightTerms(shift=1.0), LightBuffers(normal=self.normal))

    def test_no_buffers_at_all(self):
        with pytest.raises(invsss.InvalidInputError, match="light_buffers: light_terms need"):
            self._render(LightTerms(grazing=0.2), None)

    def test_wrong_shape(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.normal: expected shape \(12, 15, 3\)"):
            self._render(LightTerms(grazing=0.2), LightBuffers(normal=self.normal[..., :2]))

    def test_eight_bit_normals_are_refused(self):
        encoded = np.round((self.normal * 0.5 + 0.5) * 255)
        with pytest.raises(invsss.InvalidInputError, match="expected unit vectors.*decoded"):
            self._render(LightTerms(grazing=0.2), LightBuffers(normal=encoded))

    def test_nan_on_the_mask(self):
        light = self.light.copy()
        light[5, 5] = np.nan
        with pytest.raises(invsss.InvalidInputError, match=r"light_buffers\.light: NaN"):
            self._render(LightTerms(shift=1.0), LightBuffers(light=light))

    def test_grazing_gain_must_stay_positive(self):
        with pytest.raises(invsss.InvalidInputError, match=r"light_terms\.grazing: expected a value > -1"):
            self._render(LightTerms(grazing=-1.0), LightBuffers(normal=self.normal))

    def test_zero_vectors_off_the_mask_are_accepted(self):
        light = self.light.copy()
        light[:2] = 0.0  # the rows the mask leaves out, as a renderer writes them
        out = self._render(LightTerms(shift=1.0), LightBuffers(light=light))
        assert np.all(np.isfinite(np.asarray(out)))


class TestTorchTwin:
    torch = pytest.importorskip("torch")

    def test_values_and_gradients_agree(self):
        torch = self.torch
        import invsss.torch as itorch

        image, depth, mask, light, normal, params = _scene(1)
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
        light = torch.tensor(_unit(rng.normal(size=(6, 8, 3)) + [0, 0, 2]), dtype=torch.float64)
        offsets = itorch.propagation_offsets(light)

        def f(kappa):
            return itorch.shift_image(image, kappa * offsets)

        assert torch.autograd.gradcheck(f, (torch.tensor(0.731, dtype=torch.float64, requires_grad=True),))


# ------------------------------------------------------------------ estimator


def _lit_pair(size=48):
    """A model-made pair with both terms: a textured card turning away from the
    camera (normals from -45 to 45 degrees), lit from the upper left, with dark
    vertical stripes so that the shift moves edges."""
    rng = np.random.default_rng(0)
    source = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, (size, size)), 1.5) * 2.0 + 0.3
    source[:, 18:22] *= 0.3
    source[:, 32:34] *= 0.4
    depth = np.full((size, size), 500.0) + np.linspace(0.0, 30.0, size)[None]
    light = np.zeros((size, size, 3))
    light[..., 0], light[..., 1] = -0.5, 0.3
    light[..., 2] = np.sqrt(1.0 - 0.34)
    normal = np.zeros((size, size, 3))
    normal[..., 0] = np.linspace(-0.7, 0.7, size)[None]
    normal[..., 2] = np.sqrt(1.0 - normal[..., 0] ** 2)
    mask = np.zeros((size, size))
    mask[2:-2, 2:-2] = 1.0
    return source, depth, mask, LightBuffers(normal=normal, light=light)


PROFILE = {"weights": [0.5, 0.5], "variances": [0.5, 2.0]}
FIX = {"correction": 0.0, "maxdd": 1.0}


@pytest.mark.slow
def test_fit_recovers_the_terms_and_the_blur():
    source, depth, mask, buffers = _lit_pair()
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    terms = LightTerms(shift=1.2, grazing=0.3)
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=terms, light_buffers=buffers))
    target = target + np.random.default_rng(1).normal(0.0, 0.002, target.shape)
    fit = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2,
                          light_terms=("shift", "grazing"), light_buffers=buffers)
    assert fit.converged
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.02)
    assert fit.light_terms["shift"] == pytest.approx(1.2, abs=0.05)
    assert fit.light_terms["grazing"] == pytest.approx(0.3, abs=0.01)
    # Honest errors: the truth lies within 4 standard errors.
    for name, true in (("shift", 1.2), ("grazing", 0.3)):
        err = fit.light_terms["stderr"][name]
        assert err is not None and 0 < err and abs(fit.light_terms[name] - true) < 4 * err
    # Without the terms the same data give a biased blur and a worse fit.
    plain = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2)
    assert plain.light_terms is None
    assert plain.psnr < fit.psnr - 3.0
    record = fit.to_dict()["light_terms"]
    assert set(record) == {"shift", "grazing", "stderr", "fixed", "psnr_plain", "psnr_without"}
    assert record["fixed"] == []
    # What the terms bought, measured: the fit started from the plain fit.
    assert record["psnr_plain"] == pytest.approx(plain.psnr, abs=1e-9)
    assert set(record["psnr_without"]) == {"shift", "grazing"}
    assert all(value < fit.psnr - 0.05 for value in record["psnr_without"].values())


def _dome_pair(size=40):
    """A model-made pair for the incidence term: a textured dome lit from the upper
    left, so that the view angle (n_z) and the key light's incidence (n . l) vary
    in different directions and the grazing and incidence gains can be told apart."""
    rng = np.random.default_rng(2)
    source = ndimage.gaussian_filter(rng.uniform(0.0, 1.0, (size, size)), 1.5) * 2.0 + 0.3
    source[:, 14:17] *= 0.3
    y, x = (np.mgrid[0:size, 0:size] - (size - 1) / 2.0) / (size / 2.0)
    r2 = np.minimum(x**2 + y**2, 0.9)
    normal = np.stack([0.9 * x, -0.9 * y, np.sqrt(1.0 - 0.81 * r2)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    depth = 500.0 - 40.0 * np.sqrt(1.0 - 0.81 * r2)
    light = np.broadcast_to(np.array([-0.6, 0.3, np.sqrt(1.0 - 0.45)]), (size, size, 3)).copy()
    mask = (x**2 + y**2 < 0.85).astype(float)
    return source, depth, mask, LightBuffers(normal=normal, light=light)


@pytest.mark.slow
def test_fit_recovers_the_incidence_gain_beside_the_other_terms():
    source, depth, mask, buffers = _dome_pair()
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    terms = LightTerms(shift=1.0, grazing=0.3, incidence=0.4)
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=terms, light_buffers=buffers))
    target = target + np.random.default_rng(1).normal(0.0, 0.002, target.shape)
    fit = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2,
                          light_terms="shift,grazing,incidence", light_buffers=buffers)
    assert fit.converged
    assert float(fit.params.sss_level) == pytest.approx(600.0, rel=0.03)
    for name in ("shift", "grazing", "incidence"):
        err, true = fit.light_terms["stderr"][name], getattr(terms, name)
        assert err is not None and 0 < err < 0.1
        assert abs(fit.light_terms[name] - float(true)) < 4 * err
    # Without the incidence term the same data are fitted worse.
    two = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=2,
                          light_terms="shift,grazing", light_buffers=buffers)
    assert two.psnr < fit.psnr - 3.0
    assert fit.light_terms_params().incidence == pytest.approx(fit.light_terms["incidence"])


@pytest.mark.slow
def test_params_file_keeps_the_terms(tmp_path):
    source, depth, mask, buffers = _lit_pair(24)
    target = np.asarray(invsss.render(source, depth, mask, invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0]),
                                      light_terms=LightTerms(shift=1.0), light_buffers=buffers))
    fit = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1,
                          light_terms="shift", light_buffers=buffers)
    path = tmp_path / "params.json"
    invsss.write_params(path, fit.to_dict())
    import json

    stored = json.loads(path.read_text())["light_terms"]
    assert stored["shift"] == pytest.approx(fit.light_terms["shift"]) and "grazing" not in stored
    invsss.read_params(path)  # the strict params file accepts the new key


def test_fit_without_the_buffer_names_it_before_fitting():
    # Before the plain fit that comes first (it used to run to the end): no slow mark.
    source, depth, mask, buffers = _lit_pair(16)
    with pytest.raises(invsss.InvalidInputError, match=r"^light_buffers\.normal: the 'grazing' term needs this buffer"):
        invsss.fit_pair(source, source, depth, mask, light_terms=["grazing"],
                        light_buffers=LightBuffers(light=buffers.light))
    with pytest.raises(invsss.InvalidInputError, match=r"^pairs\[1\]\.light: the 'shift' term needs this buffer"):
        invsss.fit_pairs([invsss.ImagePair(source, source, depth, mask, light=buffers.light), (source, source, depth, mask)],
                         light_terms=["shift"])
    with pytest.raises(invsss.InvalidInputError, match=r"light_terms: unknown term\(s\) 'tilt'"):
        invsss.fit_pair(source, source, depth, mask, light_terms=["tilt"], light_buffers=buffers)


@pytest.mark.slow
def test_cli_fit_with_light_terms(tmp_path, capsys):
    import json

    from _pair_files import pair_args, write_pair
    from invsss.cli import main

    source, depth, mask, buffers = _lit_pair(32)
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=LightTerms(shift=1.2),
                                      light_buffers=buffers))
    paths = write_pair(tmp_path, "lit", (source, target, depth, mask))
    invsss.write_image(tmp_path / "light.exr", np.asarray(buffers.light, np.float32))
    profile = tmp_path / "profile.json"
    profile.write_text(json.dumps(PROFILE))
    common = [*pair_args(paths), "--profile", str(profile), "--fix", "correction=0", "maxdd=1", "--starts", "1"]
    assert main(["fit", *common, "--light-terms", "shift", "--light", str(tmp_path / "light.exr"),
                 "--out", str(tmp_path / "fit")]) == 0
    stored = json.loads((tmp_path / "fit" / "params.json").read_text())
    assert stored["light_terms"]["shift"] == pytest.approx(1.2, abs=0.05)
    # Asking for the term without its buffer is a one-line error, nothing written.
    capsys.readouterr()
    assert main(["fit", *common, "--light-terms", "shift", "--out", str(tmp_path / "bad")]) != 0
    err = capsys.readouterr().err
    assert "invsss: error: --light: the 'shift' term needs this buffer" in err and "Traceback" not in err

    # invsss render applies the fitted terms: the library's render with the same
    # values, and not the blur alone.
    params_path = str(tmp_path / "fit" / "params.json")
    scene = ["--image", str(paths["source"]), "--depth", str(paths["depth"]), "--mask", str(paths["mask"]),
             "--params", params_path]
    assert main(["render", *scene, "--light", str(tmp_path / "light.exr"), "--out", str(tmp_path / "lit.exr")]) == 0
    assert "light terms shift=" in capsys.readouterr().out
    fitted, _ = invsss.read_params(params_path)
    expected = np.asarray(invsss.render(source, depth, mask, fitted,
                                        light_terms=LightTerms(shift=stored["light_terms"]["shift"]),
                                        light_buffers=LightBuffers(light=invsss.read_image(tmp_path / "light.exr"))))
    rendered = invsss.read_image(tmp_path / "lit.exr")
    np.testing.assert_allclose(rendered, expected.reshape(rendered.shape), atol=1e-5)
    assert main(["render", *scene, "--no-light-terms", "--out", str(tmp_path / "plain.exr")]) == 0
    plain = invsss.read_image(tmp_path / "plain.exr")
    assert np.abs(plain - rendered).max() > 1e-2
    # Terms in the params file without their buffer: one line naming the flag.
    capsys.readouterr()
    assert main(["render", *scene, "--out", str(tmp_path / "bad.exr")]) != 0
    err = capsys.readouterr().err
    assert "holds the 'shift' light term, which needs --light" in err and "Traceback" not in err


@pytest.mark.slow
def test_an_aligned_fit_with_the_shift_warns_that_the_warp_can_take_it():
    source, depth, mask, buffers = _lit_pair(32)
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=LightTerms(shift=1.0),
                                      light_buffers=buffers))
    fit = invsss.fit_pair(source, target, depth, mask, profile=PROFILE, fix=FIX, n_starts=1, max_steps=30,
                          align="translation", light_terms="shift", light_buffers=buffers)
    assert any(w.startswith("light_terms: the shift term moves the image") for w in fit.warnings)
    assert fit.light_terms is not None and "shift" in fit.light_terms


@pytest.mark.slow
def test_a_held_shift_is_kept_and_stops_pulling_the_warp():
    # kappa measured on a registered pair and held while aligning: the
    # registration rounds render the prediction with the held shift, so the warp
    # ends nearer the truth (no misregistration here) than with the shift held
    # at 0, where the warp has to take the light's shift. The rounds converge
    # slowly (docs/model.md, section 8), so only the ordering is asserted.
    source, depth, mask, buffers = _lit_pair(48)
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=LightTerms(shift=1.2, grazing=0.3),
                                      light_buffers=buffers))
    common = dict(profile=PROFILE, fix=FIX, n_starts=1, align="translation", light_buffers=buffers)
    held = invsss.fit_pair(source, target, depth, mask, light_terms="shift=1.2,grazing", **common)
    none = invsss.fit_pair(source, target, depth, mask, light_terms={"shift": 0.0, "grazing": None}, **common)
    assert held.light_terms["shift"] == 1.2 and held.light_terms["fixed"] == ["shift"]
    assert held.light_terms["stderr"]["shift"] is None and held.light_terms["stderr"]["grazing"] is not None
    assert np.hypot(*held.alignment[0]["shift_px"]) < 0.6 * np.hypot(*none.alignment[0]["shift_px"])
    assert any(w.startswith("light_terms: with the shift held") for w in held.warnings)


@pytest.mark.parametrize("terms, message", [
    ("shift=abc", r"light_terms\['shift'\]: expected a number or None"),
    ({"grazing": -2.0}, r"light_terms\['grazing'\]: expected a finite number > -1"),
])
def test_held_values_are_checked(terms, message):
    from invsss.estimator import FitOptions

    with pytest.raises(invsss.InvalidInputError, match=message):
        FitOptions(light_terms=terms)


@pytest.mark.slow
def test_sweep_fits_the_terms_from_pair_folder_buffers(tmp_path):
    """A sweep reads normal.exr and light.exr from the pair folder when a trial asks
    for light terms, reports kappa and gamma beside the parameters, recovers them as
    fit_pair does, and keeps the ids of trials without terms."""
    import invsss.experiments as ex
    from _pair_files import light_sweep_text, write_pair_folder
    from invsss.experiments.trials import trial_id

    source, depth, mask, buffers = _lit_pair(32)
    truth = invsss.SSSParams(600.0, 0.0, 1.0, [0.6, 0.4], [0.5, 2.0])
    target = np.asarray(invsss.render(source, depth, mask, truth, light_terms=LightTerms(shift=1.2, grazing=0.3),
                                      light_buffers=buffers))
    folder = tmp_path / "data" / "card"
    write_pair_folder(folder, (source, target, depth, mask), buffers)
    text = light_sweep_text('["", "shift,grazing"]')
    path = tmp_path / "lit.toml"
    path.write_text(text)
    experiment = ex.load(path)
    assert [t.options["light_terms"] for t in experiment.trials] == ["", "shift,grazing"]
    plain, lit = experiment.trials[0], experiment.trials[1]
    assert {"normal", "light"} <= set(plain.pairs[0])
    # Without terms the buffers and the option do not enter the id: the id of a
    # sweep made before either existed.
    older = {**plain.config, "pairs": [{k: v for k, v in plain.pairs[0].items() if k not in ("normal", "light")}]}
    older["options"] = {k: v for k, v in older["options"].items() if k != "light_terms"}
    assert plain.id == trial_id(older)
    assert "normal" in lit.config["pairs"][0]

    ex.run(path, tmp_path / "out")
    rows = {r["light_terms"]: r for r in ex.results(tmp_path / "out", frame=False)}
    assert all(r["status"] == "done" for r in rows.values())
    assert rows["shift,grazing"]["param.light_shift"] == pytest.approx(1.2, abs=0.05)
    assert rows["shift,grazing"]["param.grazing"] == pytest.approx(0.3, abs=0.01)
    assert rows["shift,grazing"]["stderr.light_shift"] > 0
    assert rows[""]["param.light_shift"] is None and rows[""]["param.grazing"] is None
    assert rows["shift,grazing"]["psnr"] > rows[""]["psnr"] + 3.0


def test_sweep_refuses_light_terms_without_the_buffer(tmp_path):
    import invsss.experiments as ex
    from _pair_files import write_pair_folder

    source, depth, mask, _ = _lit_pair(16)
    write_pair_folder(tmp_path / "data" / "card", (source, source, depth, mask))
    path = tmp_path / "lit.toml"
    path.write_text('task = "fit"\n[data]\npairs = ["data/card/"]\n[base]\nlight_terms = ["shift"]\n')
    with pytest.raises(invsss.InvalidInputError, match=r"lit\.toml: trial 1 \(pair='card'\): light term 'shift' needs light\.exr "
                                                        r"in pair 'card'"):
        ex.load(path)
    path.write_text('task = "fit"\n[data]\npairs = ["data/card/"]\n[base]\nlight_terms = "tilt"\n')
    with pytest.raises(invsss.InvalidInputError, match=r"light_terms: unknown term"):
        ex.load(path)
