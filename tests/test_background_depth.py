"""Renderer-style depth: 0 or +inf off the mask is accepted by render and fit.

The reference in each test is the same pair with a finite background that
continues the surface flat, which is what the background must act like; the
depth is built flat near the mask edge so that this reference is unambiguous.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import invsss
from invsss.cli import main
from invsss.forward.pair import fill_background_depth
from invsss.validation import InvalidInputError

H, W = 20, 24
PARAMS = invsss.SSSParams(600.0, 300.0, 0.02, [0.4, 0.6], [0.3, 1.5])


def _scene():
    """Image, finite depth (a bump on a 500 mm plane, flat at the mask edge), mask."""
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r2 = ((x - 11.5) / 6.0) ** 2 + ((y - 9.5) / 5.0) ** 2
    depth = 500.0 - 25.0 * np.clip(1.0 - r2, 0.0, None) ** 2
    mask = np.zeros((H, W))
    mask[3:17, 4:20] = 1.0
    image = 0.2 + 0.6 * rng.random((H, W, 3))
    return image, depth, mask


def _renderer_depth(depth, mask, background):
    return np.where(mask > 0, depth, background)


@pytest.mark.parametrize("background", [0.0, np.inf])
def test_render_with_renderer_background_equals_finite_background(background):
    image, depth, mask = _scene()
    expected = np.asarray(invsss.render(image, depth, mask, PARAMS))
    got = np.asarray(invsss.render(image, _renderer_depth(depth, mask, background), mask, PARAMS))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got[mask > 0], expected[mask > 0], rtol=1e-6)


@pytest.mark.slow
def test_fit_with_renderer_background_equals_finite_background():
    image, depth, mask = _scene()
    target = np.asarray(invsss.render(image, depth, mask, PARAMS, model="sog"))
    options = dict(n_starts=1, max_steps=15)
    reference = invsss.fit_pair(image, target, depth, mask, **options)
    for background in (0.0, np.inf):
        result = invsss.fit_pair(
            image, target, _renderer_depth(depth, mask, background), mask, **options
        )
        assert np.isfinite(result.loss)
        np.testing.assert_allclose(result.loss, reference.loss, rtol=1e-6)
        np.testing.assert_allclose(
            np.asarray(result.params.variances), np.asarray(reference.params.variances), rtol=1e-6
        )


def test_masked_pixel_without_depth_is_refused():
    image, depth, mask = _scene()
    holed = depth.copy()
    holed[5, 6] = 0.0  # inside the mask
    with pytest.raises(InvalidInputError, match=r"^depth: .*1 masked pixel\(s\)"):
        invsss.render(image, holed, mask, PARAMS)
    with pytest.raises(InvalidInputError, match=r"^depth: .*1 masked pixel\(s\)"):
        invsss.fit_pair(image, image, holed, mask)


def test_fill_copies_the_nearest_valid_depth():
    depth = np.array([[np.inf, 510.0, 520.0], [0.0, 500.0, np.nan], [-1.0, 0.0, 0.0]])
    filled = fill_background_depth(depth)
    np.testing.assert_array_equal(
        filled, [[510.0, 510.0, 520.0], [500.0, 500.0, 500.0], [500.0, 500.0, 500.0]]
    )
    finite = np.full((3, 3), 400.0)
    assert fill_background_depth(finite) is finite  # nothing to do: no copy
    with pytest.raises(InvalidInputError, match="no pixel"):
        fill_background_depth(np.zeros((3, 3)))


@pytest.fixture
def files(tmp_path):
    image, depth, mask = _scene()
    paths = {k: tmp_path / n for k, n in [("image", "image.exr"), ("mask", "mask.png"),
                                           ("params", "params.json"), ("out", "out.exr")]}
    invsss.write_image(paths["image"], image.astype(np.float32))
    invsss.write_image(paths["mask"], mask.astype(np.float32))
    params = {k: np.asarray(getattr(PARAMS, k)).tolist() for k in
              ("sss_level", "correction", "maxdd", "weights", "variances")}
    paths["params"].write_text(json.dumps(params))
    for name, background in [("finite", None), ("zero", 0.0), ("inf", np.inf)]:
        stored = depth if background is None else _renderer_depth(depth, mask, background)
        # .npy: write_image refuses inf, as it should for images.
        paths[name] = tmp_path / f"depth_{name}.npy"
        np.save(paths[name], stored.astype(np.float32))
    holed = depth.copy()
    holed[5, 6] = 0.0
    paths["holed"] = tmp_path / "depth_holed.exr"
    invsss.write_image(paths["holed"], holed.astype(np.float32))
    return paths


def _render_cli(paths, depth_key, out):
    return main(["render", "--image", str(paths["image"]), "--depth", str(paths[depth_key]),
                 "--mask", str(paths["mask"]), "--params", str(paths["params"]),
                 "--out", str(out), "--no-cache"])


def test_cli_render_accepts_renderer_depth(files, tmp_path):
    mask = invsss.read_mask(files["mask"]) > 0
    assert _render_cli(files, "finite", tmp_path / "finite.exr") == 0
    expected = invsss.read_image(tmp_path / "finite.exr")
    for key in ("zero", "inf"):
        assert _render_cli(files, key, tmp_path / f"{key}.exr") == 0
        got = invsss.read_image(tmp_path / f"{key}.exr")
        np.testing.assert_allclose(got[mask], expected[mask], rtol=1e-6)


def test_cli_render_names_the_depth_file_of_a_masked_hole(files, tmp_path, capsys):
    assert _render_cli(files, "holed", tmp_path / "holed_out.exr") == 2
    err = capsys.readouterr().err.strip()
    assert "depth_holed.exr" in err and "1 masked pixel(s)" in err and "\n" not in err


@pytest.mark.parametrize("background", [0.0, np.inf])
def test_torch_twin_accepts_renderer_background_like_the_jax_model(background):
    torch = pytest.importorskip("torch")
    import invsss.torch as itorch

    image, depth, mask = _scene()
    p = PARAMS
    twin = itorch.SSSParams(
        float(p.sss_level), float(p.correction), float(p.maxdd),
        np.asarray(p.weights).tolist(), np.asarray(p.variances).tolist(),
    )
    renderer_depth = _renderer_depth(depth, mask, background)
    expected = itorch.render(torch.as_tensor(image), torch.as_tensor(depth), torch.as_tensor(mask), twin)
    got = itorch.render(torch.as_tensor(image), torch.as_tensor(renderer_depth), torch.as_tensor(mask), twin)
    assert torch.isfinite(got).all()
    np.testing.assert_allclose(got.numpy()[mask > 0], expected.numpy()[mask > 0], rtol=1e-12)
    # ... and agrees with the JAX model given the same renderer-style depth.
    jax_out = np.asarray(invsss.render(image, renderer_depth, mask, PARAMS))
    np.testing.assert_allclose(got.numpy(), jax_out, rtol=1e-4, atol=1e-6)


def _notices(folder, image, depth_map, mask_map, about: str, arrays_too: bool = False) -> list[str]:
    """The notices containing ``about`` that a pair loaded from files and fitted
    gives (then the same arrays given to the fit directly, with ``arrays_too``)."""
    import warnings

    import jax

    from invsss.estimator.inputs import prepare_pairs

    invsss.write_image(folder / "s.exr", image.astype(np.float32))
    np.save(folder / "d.npy", depth_map)
    np.save(folder / "m.npy", mask_map)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pair = invsss.load_pair(folder / "s.exr", folder / "s.exr", folder / "d.npy", folder / "m.npy")
        with jax.enable_x64(True):
            prepare_pairs([pair])
            if arrays_too:
                prepare_pairs([(image, image, depth_map, mask_map)])
    return [str(w.message) for w in caught if about in str(w.message)]


def test_a_loaded_pair_is_looked_at_for_background_once_and_on_the_depth_as_read(tmp_path):
    image, depth, mask = _scene()
    # 0 off the mask, as renderers write it: once filled, the skin's flat edge is the
    # largest depth and covers most of the frame, which read as a far plane before.
    assert _notices(tmp_path, image, _renderer_depth(depth, mask, 0.0), mask, "far plane") == []
    # A far plane the mask reaches into: one notice, naming the file, not a second as "mask".
    leaky = mask.copy()
    leaky[0, 0] = 1.0
    far = np.where(leaky > 0, depth, 1e4)
    far[0, 0] = 1e4
    found = _notices(tmp_path, image, far, leaky, "far plane")
    assert len(found) == 1 and found[0].startswith(str(tmp_path / "m.npy"))


def test_a_soft_rim_may_lack_depth_where_the_background_does():
    # An anti-aliased mask reaches into pixels whose depth saw the background (0):
    # filled like the background, not refused (the rim used to be "293 masked pixels").
    image, depth, mask = _scene()
    soft = mask.copy()
    soft[2, 4:20] = soft[17, 4:20] = 0.5  # a rim above and below the hard mask
    renderer = _renderer_depth(depth, mask, 0.0)  # no depth on the rim
    got = np.asarray(invsss.render(image, renderer, soft, PARAMS))
    expected = np.asarray(invsss.render(image, fill_background_depth(renderer), soft, PARAMS))
    np.testing.assert_array_equal(got, expected)
    assert np.all(np.isfinite(got))
    # Where the mask is 1 a missing depth is still an error.
    holed = renderer.copy()
    holed[5, 6] = np.nan
    with pytest.raises(InvalidInputError, match=r"^depth: expected finite depth > 0 wherever the mask is 1, 1 masked"):
        invsss.render(image, holed, soft, PARAMS)


def test_depth_in_whole_millimetres_is_noted_once_and_smooth_depth_is_not(tmp_path):
    image, depth, mask = _scene()  # slopes of up to 4 mm a pixel on the bump, 0 on the flat edge
    y, x = np.mgrid[0:H, 0:W]
    smooth = depth + 0.2 * x + 0.15 * y  # and a tilt: no two neighbours at one depth
    assert _notices(tmp_path, image, smooth, mask, "comes in steps of", arrays_too=True) == []
    found = _notices(tmp_path, image, np.round(smooth), mask, "comes in steps of", arrays_too=True)
    # Once for the file, once for the same arrays given directly: not twice for the file.
    assert [m.split(":")[0] for m in found] == [str(tmp_path / "d.npy"), "depth"]
