"""File I/O: round trips, colour decoding, and one-line errors naming the file."""

from __future__ import annotations

import json
import math
import os
import warnings

import numpy as np
import OpenImageIO as oiio
import pytest

import invsss
from invsss.io import linear_to_srgb, srgb_to_linear
from invsss.validation import InvalidInputError
from tests.forward._notices import input_notices
from tests.io._scene_files import H, W, fitted_params_file, scene_files


def _write_raw(path, pixels, pixel_type, channel_names=None, colour_space=None):
    """Write exact stored values with OpenImageIO, bypassing invsss's encoding."""
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[..., None]
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], pixel_type)
    if channel_names is not None:
        spec.channelnames = channel_names
    if colour_space is not None:
        spec.attribute("oiio:ColorSpace", colour_space)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(pixels), out.geterror()
    out.close()
    return str(path)


def _reference_srgb_eotf(code: int, bits: int = 8) -> float:
    c = code / (2**bits - 1)
    return c / 12.92 if c <= 0.04045 else math.pow((c + 0.055) / 1.055, 2.4)


@pytest.fixture
def rgb():
    return np.random.default_rng(1).random((H, W, 3)).astype(np.float32)


def _raises(func, *args, match_file, **kwargs) -> str:
    """Call ``func``; it must raise a one-line InvalidInputError naming ``match_file``."""
    with pytest.raises(InvalidInputError) as info:
        func(*args, **kwargs)
    message = str(info.value)
    assert os.path.basename(str(match_file)) in message
    assert "\n" not in message
    return message


# ------------------------------------------------------------------ round trips


@pytest.mark.parametrize("ext", ["exr", "tif", "npy"])
def test_float_formats_round_trip_exactly(tmp_path, rgb, ext):
    path = tmp_path / f"image.{ext}"
    invsss.write_image(path, rgb)
    back = invsss.read_image(path)
    assert back.dtype == np.float32 and back.shape == (H, W, 3)
    np.testing.assert_array_equal(back, rgb)


def test_grey_image_gains_a_channel_axis(tmp_path, rgb):
    path = tmp_path / "grey.exr"
    invsss.write_image(path, rgb[..., 0])
    back = invsss.read_image(path)
    assert back.shape == (H, W, 1)
    np.testing.assert_array_equal(back[..., 0], rgb[..., 0])


def test_half_exr_round_trips_to_half_precision(tmp_path, rgb):
    path = tmp_path / "half.exr"
    invsss.write_image(path, rgb, bits=16)
    back = invsss.read_image(path)
    np.testing.assert_allclose(back, rgb, rtol=2.0**-11, atol=2.0**-24)
    assert not np.array_equal(back, rgb)  # it really was stored as half


@pytest.mark.parametrize("ext", ["png", "tif"])
def test_8bit_round_trip_is_sRGB_quantised(tmp_path, rgb, ext):
    path = tmp_path / f"image8.{ext}"
    invsss.write_image(path, rgb, bits=8)
    back = invsss.read_image(path)
    # Quantisation happens in the encoded domain: at most half a code there.
    error = np.abs(linear_to_srgb(back) - linear_to_srgb(rgb))
    assert error.max() <= 0.5 / 255 + 1e-6


@pytest.mark.parametrize("ext", ["png", "tif"])
def test_16bit_round_trip_is_linear_quantised(tmp_path, rgb, ext):
    path = tmp_path / f"image16.{ext}"
    invsss.write_image(path, rgb, bits=16)
    back = invsss.read_image(path)
    assert np.abs(back - rgb).max() <= 0.5 / 65535 + 1e-7


def test_png_defaults_to_8bit_srgb(tmp_path):
    path = tmp_path / "mid.png"
    invsss.write_image(path, np.full((4, 4), 0.5, np.float32))
    stored = oiio.ImageInput.open(str(path))
    codes = stored.read_image(format="uint8")
    stored.close()
    # linear 0.5 is sRGB code round(255 * 0.7354) = 188, not 128
    assert codes.dtype == np.uint8 and int(codes[0, 0, 0]) == 188


def test_jpeg_round_trip_is_close_on_a_smooth_image(tmp_path):
    y, x = np.mgrid[0:24, 0:32]
    smooth = np.stack([x / 31, y / 23, (x + y) / 54], axis=-1).astype(np.float32)
    path = tmp_path / "image.jpg"
    invsss.write_image(path, smooth)
    back = invsss.read_image(path)
    assert back.shape == smooth.shape
    # Lossy: a tolerance on the mean, and a loose one on the worst pixel.
    assert np.abs(back - smooth).mean() < 0.01
    assert np.abs(back - smooth).max() < 0.08


def test_write_leaves_no_temporary_files_and_replaces_old_content(tmp_path, rgb):
    path = tmp_path / "out.exr"
    invsss.write_image(path, np.zeros((H, W, 3), np.float32))
    invsss.write_image(path, rgb)
    np.testing.assert_array_equal(invsss.read_image(path), rgb)
    assert sorted(os.listdir(tmp_path)) == ["out.exr"]


def test_failed_write_keeps_the_old_file_and_leaves_nothing_else(tmp_path, rgb):
    path = tmp_path / "out.png"
    invsss.write_image(path, rgb)
    before = path.read_bytes()
    bad = rgb.copy()
    bad[0, 0, 0] = np.nan
    _raises(invsss.write_image, path, bad, match_file=path)
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["out.png"]


# ------------------------------------------------------------- colour decoding


def test_8bit_png_is_decoded_with_the_exact_srgb_eotf(tmp_path):
    # 10 is below the 0.04045 knee (linear segment), 11 just above it.
    codes = np.array([0, 1, 10, 11, 64, 128, 200, 254, 255], np.uint8)
    path = _write_raw(tmp_path / "codes.png", np.tile(codes, (2, 1)), "uint8")
    decoded = invsss.read_image(path)[0, :, 0]
    expected = np.array([_reference_srgb_eotf(int(c)) for c in codes])
    np.testing.assert_allclose(decoded, expected, rtol=1e-6, atol=1e-9)
    # Published value: sRGB 128 is 21.586 % linear.
    assert abs(float(decoded[5]) - 0.21586) < 1e-5


def test_jpeg_and_8bit_tiff_are_srgb(tmp_path):
    codes = np.full((4, 4), 128, np.uint8)
    for name in ("grey.tif", "grey.jpg"):
        path = _write_raw(tmp_path / name, codes, "uint8")
        np.testing.assert_allclose(invsss.read_image(path), _reference_srgb_eotf(128), rtol=1e-6)


def test_16bit_png_is_linear_despite_its_default_srgb_label(tmp_path):
    path = _write_raw(tmp_path / "plain16.png", np.full((4, 4), 30000, np.uint16), "uint16")
    stored = oiio.ImageInput.open(path)
    label = stored.spec().get_string_attribute("oiio:ColorSpace")
    stored.close()
    assert oiio.equivalent_colorspace(label, "srgb_rec709_scene")  # why the rule exists
    # Read as linear, and said so, as the 8-bit half of the rule is (an editor's
    # 16-bit export is sRGB, and nothing else would tell).
    with pytest.warns(invsss.InputNotice, match=r"plain16.png: 16-bit codes read as linear values \(the file does not say"):
        image = invsss.read_image(path)
    np.testing.assert_allclose(image, 30000 / 65535, rtol=1e-6)
    # Declared linear (linear=True): nothing to say.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        invsss.read_image(path, linear=True)


def test_declared_colour_spaces_override_the_bit_depth_default(tmp_path):
    linear8 = _write_raw(tmp_path / "lin8.png", np.full((4, 4), 128, np.uint8), "uint8",
                         colour_space="lin_rec709_scene")
    np.testing.assert_allclose(invsss.read_image(linear8), 128 / 255, rtol=1e-6)
    gamma16 = _write_raw(tmp_path / "g22.png", np.full((4, 4), 30000, np.uint16), "uint16",
                         colour_space="g22_rec709_scene")
    np.testing.assert_allclose(invsss.read_image(gamma16), (30000 / 65535) ** 2.2, rtol=1e-5)
    srgb16 = _write_raw(tmp_path / "srgb16.tif", np.full((4, 4), 30000, np.uint16), "uint16",
                        colour_space="srgb_rec709_scene")
    np.testing.assert_allclose(
        invsss.read_image(srgb16), _reference_srgb_eotf(30000, bits=16), rtol=1e-6
    )


def test_srgb_functions_invert_each_other():
    x = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, atol=1e-12)
    # The two published branches meet at the knee to within ~2e-9 (the standard's
    # rounded constants): a swapped or mistyped branch would be off by far more.
    assert abs(float(srgb_to_linear(0.04045)) - float(srgb_to_linear(0.04046))) < 1e-6


def test_alpha_and_z_channels_are_dropped(tmp_path, rgb):
    rgba = np.concatenate([rgb, np.ones((H, W, 1), np.float32)], axis=-1)
    path = _write_raw(tmp_path / "rgba.exr", rgba, "float", ("R", "G", "B", "A"))
    np.testing.assert_array_equal(invsss.read_image(path), rgb)
    grey_alpha = _write_raw(tmp_path / "ya.png", np.full((4, 4, 2), 255, np.uint8), "uint8",
                            ("Y", "A"))
    assert invsss.read_image(grey_alpha).shape == (4, 4, 1)


# ------------------------------------------------------------------ depth, mask


def test_depth_from_exr_npy_and_16bit_png(tmp_path):
    depth = np.linspace(400.0, 600.0, H * W, dtype=np.float32).reshape(H, W)
    exr = tmp_path / "depth.exr"
    invsss.write_image(exr, depth)
    np.testing.assert_array_equal(invsss.read_depth(exr), depth)
    np.testing.assert_allclose(invsss.read_depth(exr, scale=0.5), depth * 0.5, rtol=1e-7)

    npy = tmp_path / "depth.npy"
    np.save(npy, depth.astype(np.float64) / 1000.0)
    np.testing.assert_allclose(invsss.read_depth(npy, scale=1000.0), depth, rtol=1e-6)

    codes = np.arange(1, H * W + 1, dtype=np.uint16).reshape(H, W) * 200
    png = _write_raw(tmp_path / "depth16.png", codes, "uint16")
    got = invsss.read_depth(png, scale=0.1)
    assert got.dtype == np.float32 and got.shape == (H, W)
    np.testing.assert_allclose(got, codes * 0.1, rtol=1e-6)  # raw codes, no sRGB, no /65535


def test_depth_prefers_a_named_z_channel(tmp_path, rgb):
    z = np.full((H, W, 1), 321.0, np.float32)
    path = _write_raw(tmp_path / "render.exr", np.concatenate([rgb, z], -1), "float",
                      ("R", "G", "B", "Z"))
    np.testing.assert_array_equal(invsss.read_depth(path), z[..., 0])
    np.testing.assert_array_equal(invsss.read_image(path), rgb)  # Z is not colour


def test_mask_codes_are_normalised_not_colour_decoded(tmp_path):
    codes = np.zeros((H, W), np.uint8)
    codes[2:6, 3:9] = 255
    codes[7, 7] = 128
    path = _write_raw(tmp_path / "mask.png", codes, "uint8")
    mask = invsss.read_mask(path)
    assert mask.dtype == np.float32 and mask.shape == (H, W)
    np.testing.assert_allclose(mask, codes / 255.0, rtol=1e-6)

    boolean = tmp_path / "mask.npy"
    np.save(boolean, codes > 0)
    np.testing.assert_array_equal(invsss.read_mask(boolean), (codes > 0).astype(np.float32))


# ------------------------------------------------------------------- bad input


def test_missing_files_are_named(tmp_path):
    for reader in (invsss.read_image, invsss.read_depth, invsss.read_mask, invsss.read_params):
        missing = tmp_path / ("nothere.json" if reader is invsss.read_params else "nothere.exr")
        assert "not found" in _raises(reader, missing, match_file=missing)


def test_corrupt_files_are_named(tmp_path, rgb):
    garbage = tmp_path / "garbage.png"
    garbage.write_bytes(b"this is not a png at all")
    assert "cannot read" in _raises(invsss.read_image, garbage, match_file=garbage)

    good = tmp_path / "good.exr"
    invsss.write_image(good, rgb)
    truncated = tmp_path / "truncated.exr"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    _raises(invsss.read_image, truncated, match_file=truncated)

    bad_npy = tmp_path / "bad.npy"
    bad_npy.write_bytes(b"\x93NUMPY garbage")
    _raises(invsss.read_depth, bad_npy, match_file=bad_npy)


def test_unsupported_extension_is_named(tmp_path, rgb):
    path = tmp_path / "image.bmp"
    path.write_bytes(b"BM")
    message = _raises(invsss.read_image, path, match_file=path)
    assert ".bmp" in message and ".exr" in message
    _raises(invsss.write_image, tmp_path / "out.gif", rgb, match_file="out.gif")


def test_wrong_channel_count_is_named(tmp_path):
    two = _write_raw(tmp_path / "uv.exr", np.ones((4, 4, 2), np.float32), "float", ("U", "V"))
    assert "1 or 3" in _raises(invsss.read_image, two, match_file=two)


def test_nan_image_is_named(tmp_path, rgb):
    rgb[3, 4, 1] = np.nan
    path = _write_raw(tmp_path / "nan.exr", rgb, "float")
    assert "NaN" in _raises(invsss.read_image, path, match_file=path)


def test_bad_depth_is_named(tmp_path):
    # Invalid depth on a masked pixel is refused by load_pair, naming the depth file
    # (read_depth alone cannot know the mask: renderers write 0/inf off the skin).
    paths = scene_files(tmp_path)
    depth = np.full((H, W), 500.0, np.float32)
    with_nan = depth.copy()
    with_nan[1, 1] = np.nan
    with_zero = depth.copy()
    with_zero[2, 3] = 0.0
    with_negative = depth.copy()
    with_negative[0, 0] = -1.0
    with_inf = depth.copy()
    with_inf[4, 5] = np.inf
    for name, array in [("nan.exr", with_nan), ("zero.exr", with_zero),
                        ("negative.exr", with_negative), ("inf.exr", with_inf)]:
        path = _write_raw(tmp_path / name, array, "float")
        message = _raises(invsss.load_pair, paths["source"], paths["target"], path,
                          paths["mask"], match_file=path)
        assert "> 0" in message and "1 masked pixel(s)" in message

    hole = np.full((H, W), 1000, np.uint16)
    hole[5, 5] = 0  # a depth camera's "no reading"
    png = _write_raw(tmp_path / "hole.png", hole, "uint16")
    message = _raises(invsss.load_pair, paths["source"], paths["target"], png, paths["mask"],
                      match_file=png)
    assert "1 masked pixel(s)" in message

    for name, array in [("zeros.exr", np.zeros((H, W), np.float32)), ("minus.exr", -depth)]:
        path = _write_raw(tmp_path / name, array, "float")
        assert "> 0" in _raises(invsss.read_depth, path, match_file=path)

    good = tmp_path / "good.npy"
    np.save(good, depth)
    _raises(invsss.read_depth, good, scale=-1.0, match_file="depth scale")


def test_background_depth_of_a_render_is_read_and_filled(tmp_path):
    # A renderer's depth: 0 or +inf where the mask is 0. Read as stored, then
    # load_pair hands back finite depth equal to the file's on the mask.
    paths = scene_files(tmp_path)
    mask = np.zeros((H, W), np.float32)
    mask[3:9, 4:12] = 1.0
    invsss.write_image(paths["mask"], mask)
    depth = np.linspace(400.0, 600.0, H * W, dtype=np.float32).reshape(H, W)
    for background in (0.0, np.inf):
        stored = np.where(mask > 0, depth, np.float32(background)).astype(np.float32)
        path = _write_raw(tmp_path / f"render_depth_{background}.exr", stored, "float")
        np.testing.assert_array_equal(invsss.read_depth(path), stored)
        pair = invsss.load_pair(paths["source"], paths["target"], path, paths["mask"])
        assert np.all(np.isfinite(pair.depth)) and np.all(pair.depth > 0)
        np.testing.assert_array_equal(pair.depth[mask > 0], depth[mask > 0])


def test_8bit_depth_is_rejected_with_what_is_expected(tmp_path):
    path = _write_raw(tmp_path / "depth8.png", np.full((H, W), 100, np.uint8), "uint8")
    message = _raises(invsss.read_depth, path, match_file=path)
    assert "8-bit" in message
    assert "expected float EXR, NPY, or 16-bit PNG with a scale" in message


def test_bad_masks_are_named(tmp_path):
    empty = _write_raw(tmp_path / "empty.png", np.zeros((H, W), np.uint8), "uint8")
    assert "empty" in _raises(invsss.read_mask, empty, match_file=empty)
    for name, value in [("above.exr", 1.5), ("below.exr", -0.25), ("nan.exr", np.nan)]:
        array = np.full((H, W), 0.5, np.float32)
        array[0, 0] = value
        path = _write_raw(tmp_path / name, array, "float")
        assert "[0, 1]" in _raises(invsss.read_mask, path, match_file=path)
    labels = tmp_path / "labels.npy"
    np.save(labels, np.full((H, W), 255, np.uint8))  # 0/255 labels are not a [0, 1] mask
    _raises(invsss.read_mask, labels, match_file=labels)


def test_write_image_rejects_bad_requests(tmp_path, rgb):
    _raises(invsss.write_image, tmp_path / "x.jpg", rgb, bits=16, match_file="x.jpg")
    _raises(invsss.write_image, tmp_path / "nodir" / "x.exr", rgb, match_file="x.exr")
    _raises(invsss.write_image, tmp_path / "x.exr", rgb[..., :2], match_file="x.exr")
    assert os.listdir(tmp_path) == []


# -------------------------------------------------------------------- load_pair


@pytest.mark.parametrize("target_channels", [1, 3])
def test_load_pair_reads_and_scales(tmp_path, target_channels):
    paths = scene_files(tmp_path, target_channels)
    pair = invsss.load_pair(paths["source"], paths["target"], paths["depth"], paths["mask"],
                            depth_scale=1000.0)
    assert isinstance(pair, invsss.ImagePair)
    assert pair.source.shape == (H, W, 3) and pair.target.shape == (H, W, target_channels)
    assert pair.depth.shape == (H, W) and pair.mask.shape == (H, W)
    assert all(a.dtype == np.float32 for a in (pair.source, pair.target, pair.depth, pair.mask))
    np.testing.assert_allclose(pair.depth, 500.0)
    np.testing.assert_array_equal(pair.source, invsss.read_image(paths["source"]))


@pytest.mark.parametrize("member", ["target", "depth", "mask"])
def test_load_pair_size_mismatch_names_the_file(tmp_path, member):
    paths = scene_files(tmp_path, sizes={member: (H, W + 2)})
    message = _raises(invsss.load_pair, paths["source"], paths["target"], paths["depth"],
                      paths["mask"], match_file=paths[member])
    assert f"{H}x{W}" in message and f"{H}x{W + 2}" in message


# ------------------------------------------------------------------- params JSON


PARAMS = {"sss_level": 900.0, "correction": 250.0, "maxdd": 0.01,
          "weights": [0.3, 0.7], "variances": [0.5, 2.0]}


def test_params_round_trip_with_report_keys(tmp_path):
    path = tmp_path / "params.json"
    report = {**PARAMS, "model": "thesis", "tap_weights": "jimenez",
              "stderr": np.array([1.0, 2.0]), "converged": True, "iterations": np.int64(12)}
    invsss.write_params(path, report)
    params, extras = invsss.read_params(path)
    for key in PARAMS:
        np.testing.assert_allclose(np.asarray(getattr(params, key)), PARAMS[key], rtol=1e-6)
    assert extras == {"model": "thesis", "tap_weights": "jimenez", "stderr": [1.0, 2.0],
                      "converged": True, "iterations": 12}
    assert sorted(os.listdir(tmp_path)) == ["params.json"]


def test_write_params_accepts_sssparams(tmp_path):
    path = tmp_path / "p.json"
    invsss.write_params(path, invsss.SSSParams(**PARAMS))
    params, extras = invsss.read_params(path)
    assert extras == {}
    np.testing.assert_allclose(np.asarray(params.variances), PARAMS["variances"])


def test_unknown_params_key_is_named_with_the_file(tmp_path):
    path = tmp_path / "typo.json"
    path.write_text(json.dumps({**PARAMS, "sss_levle": 3.0}))
    message = _raises(invsss.read_params, path, match_file=path)
    assert "'sss_levle'" in message and "did you mean 'sss_level'" in message
    # and the writer refuses to produce such a file
    _raises(invsss.write_params, tmp_path / "out.json", {**PARAMS, "bogus": 1},
            match_file="out.json")
    assert not (tmp_path / "out.json").exists()


@pytest.mark.parametrize(
    "content, expected",
    [
        ("{not json", "invalid JSON"),
        ("[1, 2]", "JSON object"),
        (json.dumps({k: v for k, v in PARAMS.items() if k != "maxdd"}), "maxdd"),
        (json.dumps({**PARAMS, "sss_level": -1.0}), "sss_level"),
        (json.dumps({**PARAMS, "model": "gaussian"}), "model"),
        (json.dumps({**PARAMS, "tap_weights": [1, 2, 3]}), "tap_weights"),
    ],
)
def test_bad_params_files_are_named(tmp_path, content, expected):
    path = tmp_path / "bad.json"
    path.write_text(content)
    assert expected in _raises(invsss.read_params, path, match_file=path)


def test_undetermined_values_are_filled_from_the_fit_estimate_with_a_warning(tmp_path):
    path = fitted_params_file(tmp_path, with_estimate=True)
    with pytest.warns(UserWarning, match=r"maxdd, weights\[1\], weights\[2\] not determined"):
        params, extras = invsss.read_params(path)
    assert float(params.maxdd) == 0.25
    np.testing.assert_allclose(np.asarray(params.weights), [0.6, 0.3, 0.1], rtol=1e-6)
    assert extras["filled_from_estimate"] == ["maxdd", "weights[1]", "weights[2]"]


def test_undetermined_values_without_estimate_are_an_error(tmp_path):
    path = fitted_params_file(tmp_path, with_estimate=False)
    with pytest.raises(InvalidInputError, match=r"params.json: maxdd, weights is null"):
        invsss.read_params(path)


# ---------------------------------------------------------------- input notices


def test_srgb_decoding_is_noted_and_linear_codes_skip_it(tmp_path):
    codes = np.full((4, 4, 3), 128, np.uint8)
    path = _write_raw(tmp_path / "photo.png", codes, "uint8")
    with pytest.warns(invsss.InputNotice, match=r"photo.png: 8-bit codes decoded as sRGB.*--linear-codes"):
        decoded = invsss.read_image(path)
    np.testing.assert_allclose(decoded, _reference_srgb_eotf(128), rtol=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no notice when the user said what the codes are
        linear = invsss.read_image(path, linear=True)
    np.testing.assert_allclose(linear, 128 / 255, rtol=1e-6)


def test_linear_and_float_files_bring_no_notice(tmp_path, rgb):
    invsss.write_image(tmp_path / "a.exr", rgb)
    invsss.write_image(tmp_path / "b.png", rgb, bits=16)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        invsss.read_image(tmp_path / "a.exr")
        invsss.read_image(tmp_path / "b.png")


def test_load_pair_passes_linear_codes_to_both_images(tmp_path):
    paths = scene_files(tmp_path)
    for key in ("source", "target"):
        paths[key] = _write_raw(tmp_path / f"{key}.png", np.full((H, W, 3), 64, np.uint8), "uint8")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pair = invsss.load_pair(paths["source"], paths["target"], paths["depth"], paths["mask"],
                                linear_codes=True)
    np.testing.assert_allclose(pair.source, 64 / 255, rtol=1e-6)
    np.testing.assert_allclose(pair.target, 64 / 255, rtol=1e-6)


def test_dropping_a_translucent_alpha_is_noted(tmp_path, rgb):
    alpha = np.ones((H, W, 1), np.float32)
    opaque = _write_raw(tmp_path / "opaque.exr", np.concatenate([rgb, alpha], -1), "float",
                        ("R", "G", "B", "A"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        invsss.read_image(opaque)
    alpha[:2] = 0.5
    cut = _write_raw(tmp_path / "cut.exr", np.concatenate([rgb, alpha], -1), "float",
                     ("R", "G", "B", "A"))
    with pytest.warns(invsss.InputNotice, match=rf"cut.exr: alpha channel dropped, though {2 * W} pixel"):
        np.testing.assert_array_equal(invsss.read_image(cut), rgb)


def test_grey_rgb_mismatch_names_the_target_file(tmp_path):
    paths = scene_files(tmp_path, target_channels=3)
    grey = tmp_path / "grey_source.exr"
    invsss.write_image(grey, np.ones((H, W), np.float32))
    message = _raises(invsss.load_pair, grey, paths["target"], paths["depth"], paths["mask"],
                      match_file=paths["target"])
    assert message.startswith(f"{paths['target']}: expected 1 channel(s)")


def test_a_directory_is_not_an_image_file(tmp_path):
    (tmp_path / "dir.png").mkdir()
    message = _raises(invsss.read_image, tmp_path / "dir.png", match_file="dir.png")
    assert "expected an image file" in message


def test_an_image_read_back_can_be_written_again(tmp_path, rgb):
    invsss.write_image(tmp_path / "a.exr", rgb)
    again = invsss.read_image(tmp_path / "a.exr")
    assert again.flags["C_CONTIGUOUS"]
    invsss.write_image(tmp_path / "b.png", again[:, ::-1])  # strided input too
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        np.testing.assert_allclose(invsss.read_image(tmp_path / "b.png"), rgb[:, ::-1], atol=0.01)


def test_a_jpeg_target_is_noted_by_load_pair(tmp_path):
    paths = scene_files(tmp_path)
    notes = input_notices(lambda: invsss.load_pair(*(paths[k] for k in ("source", "target", "depth", "mask"))))
    assert not any("JPEG" in n for n in notes)
    paths["target"] = tmp_path / "target.jpg"
    invsss.write_image(paths["target"], np.full((H, W), 0.5, np.float32))
    notes = input_notices(lambda: invsss.load_pair(*(paths[k] for k in ("source", "target", "depth", "mask"))))
    jpeg = [n for n in notes if "JPEG" in n]
    assert len(jpeg) == 1 and jpeg[0].startswith(f"{paths['target']}: a JPEG target: ")
