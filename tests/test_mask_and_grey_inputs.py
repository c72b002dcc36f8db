"""Masks stored with codes 0 and 1, faint or far-from-binary masks, and grey
photographs stored as three identical channels: in the readers, `load_pair`,
`invsss render`, `invsss fit` and sweeps (issue 30, cases 1 and 2)."""

from __future__ import annotations

import json
import os
import warnings

import numpy as np
import OpenImageIO as oiio
import pytest

import invsss
import invsss.experiments as ex
from invsss.io import linear_to_srgb
from invsss.cli import main

H, W = 12, 16
FRAN = os.path.join(os.path.dirname(__file__), "..", "data_synthetic", "fran_front")


def _write_codes(path, codes, pixel_type, **attributes):
    """Write stored codes as they are, bypassing invsss's encoding."""
    codes = np.asarray(codes)
    codes = codes[..., None] if codes.ndim == 2 else codes
    spec = oiio.ImageSpec(codes.shape[1], codes.shape[0], codes.shape[2], pixel_type)
    for key, value in attributes.items():
        spec.attribute(key.replace("_", ":"), value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(np.ascontiguousarray(codes)), out.geterror()
    out.close()
    return str(path)


def _notices(func):
    """``func()``'s result and the messages of the InputNotices it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = func()
    return value, [str(w.message) for w in caught if issubclass(w.category, invsss.InputNotice)]


def _skin():
    skin = np.zeros((H, W), bool)
    skin[2:10, 3:12] = True
    return skin


# ---------------------------------------------------------------------- masks


@pytest.mark.parametrize("pixel_type,top", [("uint8", 255), ("uint16", 65535)])
def test_a_mask_of_codes_0_and_1_is_read_as_0_and_1_with_a_notice(tmp_path, pixel_type, top):
    path = _write_codes(tmp_path / "mask01.png", _skin().astype(pixel_type), pixel_type)
    mask, notes = _notices(lambda: invsss.read_mask(path))
    np.testing.assert_array_equal(mask, _skin().astype(np.float32))
    assert notes == [f"{path}: mask codes are 0 and 1 (of 0..{top}), as a boolean mask saved as "
                     "integers is; read as 0 and 1"]


def test_a_mask_of_full_codes_brings_no_notice(tmp_path):
    path = _write_codes(tmp_path / "mask.png", _skin().astype(np.uint8) * 255, "uint8")
    mask, notes = _notices(lambda: invsss.read_mask(path))
    np.testing.assert_array_equal(mask, _skin().astype(np.float32))
    assert notes == []
    # Nor do the bundled masks, or a binary mask with a soft rim.
    for name in sorted(os.listdir(os.path.join(FRAN, ".."))):
        bundled = os.path.join(FRAN, "..", name, "mask.png")
        if os.path.isfile(bundled):
            assert _notices(lambda: invsss.read_mask(bundled))[1] == []
    rim = _skin().astype(np.float32)
    rim[2, 3:12] = 0.5
    np.save(tmp_path / "rim.npy", rim)
    assert _notices(lambda: invsss.read_mask(tmp_path / "rim.npy"))[1] == []


def test_a_faint_mask_is_warned_about_naming_the_file(tmp_path):
    # An 8-bit mask's codes in a 16-bit file: 255 of 65535.
    path = _write_codes(tmp_path / "faint.png", _skin().astype(np.uint16) * 255, "uint16")
    mask, notes = _notices(lambda: invsss.read_mask(path))
    assert float(mask.max()) == pytest.approx(255 / 65535)
    assert len(notes) == 1 and notes[0].startswith(
        f"{path}: the mask's largest value is 0.00389, so no pixel is fully skin")


def test_a_mask_far_from_binary_is_warned_about_naming_the_file(tmp_path):
    photo = np.random.default_rng(0).uniform(0.05, 1.0, (H, W)).astype(np.float32)
    photo[0, 0] = 1.0
    path = tmp_path / "photo_mask.exr"
    invsss.write_image(path, photo)
    _, notes = _notices(lambda: invsss.read_mask(path))
    assert len(notes) == 1 and notes[0].startswith(f"{path}: ")
    assert "of the mask's non-zero pixels lie between 0 and 1" in notes[0]


@pytest.fixture
def scene(tmp_path):
    """A textured RGB image, sloped depth, a 0/255 mask and its 0/1 copy, and params."""
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:H, 0:W]
    paths = {k: tmp_path / n for k, n in [("image", "image.exr"), ("depth", "depth.exr"),
                                          ("mask", "mask.png"), ("mask01", "mask01.png"),
                                          ("params", "params.json")]}
    invsss.write_image(paths["image"], (0.2 + 0.6 * rng.random((H, W, 3))).astype(np.float32))
    invsss.write_image(paths["depth"], (450.0 + 2.0 * x + 0.5 * y).astype(np.float32))
    _write_codes(paths["mask"], _skin().astype(np.uint8) * 255, "uint8")
    _write_codes(paths["mask01"], _skin().astype(np.uint8), "uint8")
    paths["params"].write_text(json.dumps({"sss_level": 600.0, "correction": 300.0, "maxdd": 0.02,
                                           "weights": [0.4, 0.6], "variances": [0.3, 1.5]}))
    return paths


def test_render_with_a_0_1_mask_blurs_as_with_the_full_mask(scene, tmp_path, capsys):
    outputs = {}
    for mask in ("mask", "mask01"):
        outputs[mask] = tmp_path / f"out_{mask}.exr"
        assert main(["render", "--image", str(scene["image"]), "--depth", str(scene["depth"]),
                     "--mask", str(scene[mask]), "--params", str(scene["params"]),
                     "--out", str(outputs[mask])]) == 0
        err = capsys.readouterr().err
    np.testing.assert_array_equal(invsss.read_image(outputs["mask01"]), invsss.read_image(outputs["mask"]))
    assert f"invsss: warning: {scene['mask01']}: mask codes are 0 and 1" in err
    assert err.count("\n") == 1


def test_load_pair_with_a_0_1_mask_is_the_pair_with_the_full_mask(scene, tmp_path):
    target = tmp_path / "target.exr"
    invsss.write_image(target, np.full((H, W), 0.5, np.float32))
    full = invsss.load_pair(scene["image"], target, scene["depth"], scene["mask"])
    boolean, notes = _notices(lambda: invsss.load_pair(scene["image"], target, scene["depth"], scene["mask01"]))
    np.testing.assert_array_equal(boolean.mask, full.mask)
    assert any(n.startswith(f"{scene['mask01']}: mask codes are 0 and 1") for n in notes)


# --------------------------------------------------------- grey stored as RGB


def _grey(seed=4):
    return np.random.default_rng(seed).uniform(0.05, 0.9, (H, W)).astype(np.float32)


def _rgb_source(tmp_path):
    path = tmp_path / "source.exr"
    invsss.write_image(path, np.random.default_rng(5).uniform(0.1, 0.9, (H, W, 3)).astype(np.float32))
    return path


def _pair_files(tmp_path, source, target):
    depth, mask = tmp_path / "depth.exr", tmp_path / "mask.png"
    invsss.write_image(depth, np.full((H, W), 500.0, np.float32))
    _write_codes(mask, _skin().astype(np.uint8) * 255, "uint8")
    return source, target, depth, mask


def _grey_files(tmp_path, ext):
    """The same grey written as one channel and as three identical channels."""
    grey = _grey()
    one, three = tmp_path / f"grey1{ext}", tmp_path / f"grey3{ext}"
    if ext == ".jpg":
        # Chroma subsampled 4:2:0, as cameras write (write_image writes 4:4:4).
        codes = np.round(linear_to_srgb(grey) * 255).astype(np.uint8)
        _write_codes(one, codes, "uint8", Compression="jpeg:90", jpeg_subsampling="4:2:0")
        _write_codes(three, np.repeat(codes[..., None], 3, 2), "uint8", Compression="jpeg:90",
                     jpeg_subsampling="4:2:0")
    else:
        bits = {".png": 8, ".exr": 32, ".tif": 16}[ext]
        invsss.write_image(one, grey, bits=bits)
        invsss.write_image(three, np.repeat(grey[..., None], 3, 2), bits=bits)
    return one, three


@pytest.mark.parametrize("ext", [".png", ".jpg", ".exr", ".tif"])
def test_a_grey_target_stored_as_rgb_is_read_as_one_channel(tmp_path, ext):
    one, three = _grey_files(tmp_path, ext)
    files = _pair_files(tmp_path, _rgb_source(tmp_path), one)
    reference, _ = _notices(lambda: invsss.load_pair(*files))
    pair, notes = _notices(lambda: invsss.load_pair(files[0], three, *files[2:]))
    assert pair.target.shape == (H, W, 1)
    np.testing.assert_array_equal(pair.target, reference.target)
    np.testing.assert_array_equal(pair.source, reference.source)
    assert [n for n in notes if "channels" in n] == [
        f"{three}: its three channels are identical (a grey image stored as RGB); read as one grey channel"]
    # The reader itself returns what the file holds.
    assert _notices(lambda: invsss.read_image(three))[0].shape == (H, W, 3)


def test_half_exr_and_last_bit_differences_are_one_grey(tmp_path):
    grey = _grey()
    half = tmp_path / "half.exr"
    invsss.write_image(half, np.repeat(grey[..., None], 3, 2), bits=16)
    # A grey through a colour matrix: green one float32 step off.
    matrix = np.repeat(grey[..., None], 3, 2)
    matrix[..., 1] = np.nextafter(matrix[..., 1], np.float32(2.0))
    last_bit = tmp_path / "last_bit.exr"
    invsss.write_image(last_bit, matrix)
    for target in (half, last_bit):
        pair, _ = _notices(lambda: invsss.load_pair(*_pair_files(tmp_path, _rgb_source(tmp_path), target)))
        assert pair.target.shape == (H, W, 1)


@pytest.mark.parametrize("ext,offset", [(".png", 1), (".jpg", 2), (".exr", 1e-3)])
def test_nearly_grey_colour_stays_rgb(tmp_path, ext, offset):
    """One PNG code, two JPEG codes (which JPEG keeps: docs in invsss.io.images) or a
    float difference above the file's precision is colour."""
    grey = _grey()
    path = tmp_path / f"tinted{ext}"
    if ext == ".exr":
        tinted = np.repeat(grey[..., None], 3, 2)
        tinted[..., 0] += offset
        invsss.write_image(path, tinted)
    else:
        codes = np.repeat(np.round(linear_to_srgb(grey) * 200).astype(np.int32)[..., None], 3, 2)
        codes[..., 0] += offset
        _write_codes(path, codes.astype(np.uint8), "uint8", Compression="jpeg:95")
    pair, notes = _notices(lambda: invsss.load_pair(*_pair_files(tmp_path, _rgb_source(tmp_path), path)))
    assert pair.target.shape == (H, W, 3)
    assert not any("identical" in n for n in notes)


def test_grey_sources_and_targets_combine(tmp_path):
    one, three = _grey_files(tmp_path, ".exr")
    colour = _rgb_source(tmp_path)
    grey_source = tmp_path / "grey_source.exr"
    invsss.write_image(grey_source, np.repeat(_grey(7)[..., None], 3, 2))
    # A grey source stored as RGB before a grey target: both one channel.
    for target in (one, three):
        pair, notes = _notices(lambda: invsss.load_pair(*_pair_files(tmp_path, grey_source, target)))
        assert (pair.source.shape, pair.target.shape) == ((H, W, 1), (H, W, 1))
        assert f"{grey_source}: its three channels are identical (a grey image stored as RGB); read as " \
               "one grey channel, as the target is grey" in notes
    # Before a colour target it stays RGB: each channel gets its own weights.
    pair, notes = _notices(lambda: invsss.load_pair(*_pair_files(tmp_path, grey_source, colour)))
    assert (pair.source.shape, pair.target.shape) == ((H, W, 3), (H, W, 3))
    assert not any("identical" in n for n in notes)
    # A one-channel source and a grey target stored as RGB (refused before: 1 against 3 channels).
    grey_one = tmp_path / "grey_one.exr"
    invsss.write_image(grey_one, _grey(7))
    pair, _ = _notices(lambda: invsss.load_pair(*_pair_files(tmp_path, grey_one, three)))
    assert (pair.source.shape, pair.target.shape) == ((H, W, 1), (H, W, 1))


def test_a_sweep_reads_0_1_masks_and_grey_rgb_targets_as_load_pair_does(tmp_path):
    rng = np.random.default_rng(6)
    y, x = np.mgrid[0:H, 0:W]
    for name in ("plain", "stored"):
        folder = tmp_path / "data" / name
        folder.mkdir(parents=True)
        invsss.write_image(folder / "source.exr", rng.uniform(0.2, 1.0, (H, W, 3)).astype(np.float32)
                           if name == "plain" else invsss.read_image(tmp_path / "data" / "plain" / "source.exr"))
        invsss.write_image(folder / "depth.exr", (500.0 + 2.0 * x + 0.5 * y).astype(np.float32))
        grey = _grey()
        if name == "plain":
            invsss.write_image(folder / "target.exr", grey)
            _write_codes(folder / "mask.png", _skin().astype(np.uint8) * 255, "uint8")
        else:
            invsss.write_image(folder / "target.exr", np.repeat(grey[..., None], 3, 2))
            _write_codes(folder / "mask.png", _skin().astype(np.uint8), "uint8")
    experiment = tmp_path / "e.toml"
    experiment.write_text('task = "render"\n[data]\npairs = ["data/*/"]\n[base]\ncorrection = 300.0\n'
                          'maxdd = 0.02\nprofile = {weights = [0.4, 0.6], variances = [0.3, 1.5]}\n'
                          '[grid]\nsss_level = [600.0]\n')
    summary = ex.run(experiment, tmp_path / "out", log=None)
    assert (summary.done, summary.failed) == (2, 0)
    rows = {row["pair"]: row for row in ex.results(tmp_path / "out", frame=False)}
    assert rows["stored"]["psnr"] == rows["plain"]["psnr"]
    notes = rows["stored"]["warnings"]
    assert any(n.startswith("data/stored/mask.png: mask codes are 0 and 1") or
               "stored/mask.png: mask codes are 0 and 1" in n for n in notes)
    assert any("stored/target.exr: its three channels are identical" in n for n in notes)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["mask01", "grey_rgb"])
def test_fit_of_fran_front_with_a_0_1_mask_or_a_grey_rgb_target_is_the_reference(tmp_path, capsys, case):
    """The issue's numbers: sss_level 4082.7 (0/1 mask) and 1081.7 (grey as RGB) instead of 598.1."""
    files = {role: os.path.join(FRAN, f"{role}.{'png' if role == 'mask' else 'exr'}")
             for role in ("source", "target", "depth", "mask")}
    if case == "mask01":
        files["mask"] = _write_codes(tmp_path / "mask01.png",
                                     (invsss.read_mask(files["mask"]) > 0.5).astype(np.uint8), "uint8")
    else:
        target = invsss.read_image(files["target"])
        files["target"] = str(tmp_path / "target_rgb.exr")
        invsss.write_image(files["target"], np.repeat(target, 3, axis=2))
    out = tmp_path / "fit"
    args = [a for role, path in files.items() for a in (f"--{role}", path)]
    assert main(["fit", *args, "--out", str(out), "--no-cache"]) == 0
    err = capsys.readouterr().err
    assert ("mask codes are 0 and 1" if case == "mask01" else "its three channels are identical") in err
    fitted = json.loads((out / "params.json").read_text())
    assert fitted["sss_level"] == pytest.approx(598.1, abs=0.1)


def test_the_key_light_image_follows_a_grey_source_stored_as_rgb(tmp_path):
    """The law's key buffer must have the source's channels: one, when load_pair read a
    grey source stored as RGB as one channel (before a grey target)."""
    from invsss.cli.arguments import read_key_buffer
    from invsss.experiments.runner import _load
    from invsss.experiments.trials import Trial

    grey_source, key = tmp_path / "source.exr", tmp_path / "key.exr"
    invsss.write_image(grey_source, np.repeat(_grey(7)[..., None], 3, 2))
    invsss.write_image(key, np.repeat(0.5 * _grey(7)[..., None], 3, 2))
    one, _ = _grey_files(tmp_path, ".exr")
    files = _pair_files(tmp_path, grey_source, one)
    pair, _ = _notices(lambda: invsss.load_pair(*files))
    assert pair.source.shape == (H, W, 1)
    read, notes = _notices(lambda: read_key_buffer(key, pair.source, False))
    np.testing.assert_array_equal(read[..., 0], 0.5 * _grey(7))
    assert notes == [f"{key}: its three channels are identical (a grey image stored as RGB); read as one grey channel"]
    # A sweep's trial reads it the same way.
    roles = dict(zip(("source", "target", "depth", "mask"), files), key=key)
    trial = Trial("t", 0, "fit", {"light_terms": "law"}, ({"name": "p", **{k: os.path.basename(v) for k, v in roles.items()}},),
                  {}, str(tmp_path))
    (loaded,), _ = _notices(lambda: _load(trial))
    assert loaded.source.shape == loaded.key.shape == (H, W, 1)
    # A colour image stays as it is, asked or not.
    colour = _rgb_source(tmp_path)
    assert invsss.read_image(colour, grey=True).shape == (H, W, 3)


def test_a_jpeg_grey_may_differ_by_one_code_a_png_grey_not_at_all():
    """The tolerances themselves: a decoder that rounds each channel on its own may put a
    JPEG's grey one code apart (libjpeg does not; see JPEG_GREY_CODES)."""
    from invsss.io.images import _is_grey_rgb
    from invsss.io.rasters import Raster as _Raster

    codes = np.repeat(np.arange(H * W, dtype=np.int64).reshape(H, W, 1) % 250, 3, axis=2)
    codes[3, 4, 1] += 1
    assert _is_grey_rgb(_Raster(codes.astype(np.uint8), "srgb", "jpeg"))
    assert not _is_grey_rgb(_Raster(codes.astype(np.uint8), "srgb", "png"))
    codes[3, 4, 1] += 1
    assert not _is_grey_rgb(_Raster(codes.astype(np.uint8), "srgb", "jpeg"))
