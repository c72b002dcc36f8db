"""Masks stored with codes 0 and 1, faint or far-from-binary masks, and grey
photographs stored as three identical channels: in the readers and `load_pair`
(issue 30, cases 1 and 2). The command line and sweeps are tested in the folders of
their layers (test_mask_and_grey_inputs.py in each)."""

from __future__ import annotations

import os

import numpy as np
import pytest

import invsss
from invsss.io import linear_to_srgb
from tests.io._mask_and_grey import (
    FRAN,
    H,
    W,
    grey_files,
    grey_image,
    notices,
    pair_files,
    rgb_source,
    skin_rect,
    write_codes,
)
from tests.io._mask_and_grey import scene  # noqa: F401 (fixture)


# ---------------------------------------------------------------------- masks


@pytest.mark.parametrize("pixel_type,top", [("uint8", 255), ("uint16", 65535)])
def test_a_mask_of_codes_0_and_1_is_read_as_0_and_1_with_a_notice(tmp_path, pixel_type, top):
    path = write_codes(tmp_path / "mask01.png", skin_rect().astype(pixel_type), pixel_type)
    mask, notes = notices(lambda: invsss.read_mask(path))
    np.testing.assert_array_equal(mask, skin_rect().astype(np.float32))
    assert notes == [f"{path}: mask codes are 0 and 1 (of 0..{top}), as a boolean mask saved as "
                     "integers is; read as 0 and 1"]


def test_a_mask_of_full_codes_brings_no_notice(tmp_path):
    path = write_codes(tmp_path / "mask.png", skin_rect().astype(np.uint8) * 255, "uint8")
    mask, notes = notices(lambda: invsss.read_mask(path))
    np.testing.assert_array_equal(mask, skin_rect().astype(np.float32))
    assert notes == []
    # Nor do the bundled masks, or a binary mask with a soft rim.
    for name in sorted(os.listdir(os.path.join(FRAN, ".."))):
        bundled = os.path.join(FRAN, "..", name, "mask.png")
        if os.path.isfile(bundled):
            assert notices(lambda: invsss.read_mask(bundled))[1] == []
    rim = skin_rect().astype(np.float32)
    rim[2, 3:12] = 0.5
    np.save(tmp_path / "rim.npy", rim)
    assert notices(lambda: invsss.read_mask(tmp_path / "rim.npy"))[1] == []


def test_a_faint_mask_is_warned_about_naming_the_file(tmp_path):
    # An 8-bit mask's codes in a 16-bit file: 255 of 65535.
    path = write_codes(tmp_path / "faint.png", skin_rect().astype(np.uint16) * 255, "uint16")
    mask, notes = notices(lambda: invsss.read_mask(path))
    assert float(mask.max()) == pytest.approx(255 / 65535)
    assert len(notes) == 1 and notes[0].startswith(
        f"{path}: the mask's largest value is 0.00389, so no pixel is fully skin")


def test_a_mask_far_from_binary_is_warned_about_naming_the_file(tmp_path):
    photo = np.random.default_rng(0).uniform(0.05, 1.0, (H, W)).astype(np.float32)
    photo[0, 0] = 1.0
    path = tmp_path / "photo_mask.exr"
    invsss.write_image(path, photo)
    _, notes = notices(lambda: invsss.read_mask(path))
    assert len(notes) == 1 and notes[0].startswith(f"{path}: ")
    assert "of the mask's non-zero pixels lie between 0 and 1" in notes[0]


def test_load_pair_with_a_0_1_mask_is_the_pair_with_the_full_mask(scene, tmp_path):
    target = tmp_path / "target.exr"
    invsss.write_image(target, np.full((H, W), 0.5, np.float32))
    full = invsss.load_pair(scene["image"], target, scene["depth"], scene["mask"])
    boolean, notes = notices(lambda: invsss.load_pair(scene["image"], target, scene["depth"], scene["mask01"]))
    np.testing.assert_array_equal(boolean.mask, full.mask)
    assert any(n.startswith(f"{scene['mask01']}: mask codes are 0 and 1") for n in notes)


# --------------------------------------------------------- grey stored as RGB


@pytest.mark.parametrize("ext", [".png", ".jpg", ".exr", ".tif"])
def test_a_grey_target_stored_as_rgb_is_read_as_one_channel(tmp_path, ext):
    one, three = grey_files(tmp_path, ext)
    files = pair_files(tmp_path, rgb_source(tmp_path), one)
    reference, _ = notices(lambda: invsss.load_pair(*files))
    pair, notes = notices(lambda: invsss.load_pair(files[0], three, *files[2:]))
    assert pair.target.shape == (H, W, 1)
    np.testing.assert_array_equal(pair.target, reference.target)
    np.testing.assert_array_equal(pair.source, reference.source)
    assert [n for n in notes if "channels" in n] == [
        f"{three}: its three channels are identical (a grey image stored as RGB); read as one grey channel"]
    # The reader itself returns what the file holds.
    assert notices(lambda: invsss.read_image(three))[0].shape == (H, W, 3)


def test_half_exr_and_last_bit_differences_are_one_grey(tmp_path):
    grey = grey_image()
    half = tmp_path / "half.exr"
    invsss.write_image(half, np.repeat(grey[..., None], 3, 2), bits=16)
    # A grey through a colour matrix: green one float32 step off.
    matrix = np.repeat(grey[..., None], 3, 2)
    matrix[..., 1] = np.nextafter(matrix[..., 1], np.float32(2.0))
    last_bit = tmp_path / "last_bit.exr"
    invsss.write_image(last_bit, matrix)
    for target in (half, last_bit):
        pair, _ = notices(lambda: invsss.load_pair(*pair_files(tmp_path, rgb_source(tmp_path), target)))
        assert pair.target.shape == (H, W, 1)


@pytest.mark.parametrize("ext,offset", [(".png", 1), (".jpg", 2), (".exr", 1e-3)])
def test_nearly_grey_colour_stays_rgb(tmp_path, ext, offset):
    """One PNG code, two JPEG codes (which JPEG keeps: docs in invsss.io.images) or a
    float difference above the file's precision is colour."""
    grey = grey_image()
    path = tmp_path / f"tinted{ext}"
    if ext == ".exr":
        tinted = np.repeat(grey[..., None], 3, 2)
        tinted[..., 0] += offset
        invsss.write_image(path, tinted)
    else:
        codes = np.repeat(np.round(linear_to_srgb(grey) * 200).astype(np.int32)[..., None], 3, 2)
        codes[..., 0] += offset
        write_codes(path, codes.astype(np.uint8), "uint8", Compression="jpeg:95")
    pair, notes = notices(lambda: invsss.load_pair(*pair_files(tmp_path, rgb_source(tmp_path), path)))
    assert pair.target.shape == (H, W, 3)
    assert not any("identical" in n for n in notes)


def test_grey_sources_and_targets_combine(tmp_path):
    one, three = grey_files(tmp_path, ".exr")
    colour = rgb_source(tmp_path)
    grey_source = tmp_path / "grey_source.exr"
    invsss.write_image(grey_source, np.repeat(grey_image(7)[..., None], 3, 2))
    # A grey source stored as RGB before a grey target: both one channel.
    for target in (one, three):
        pair, notes = notices(lambda: invsss.load_pair(*pair_files(tmp_path, grey_source, target)))
        assert (pair.source.shape, pair.target.shape) == ((H, W, 1), (H, W, 1))
        assert f"{grey_source}: its three channels are identical (a grey image stored as RGB); read as " \
               "one grey channel, as the target is grey" in notes
    # Before a colour target it stays RGB: each channel gets its own weights.
    pair, notes = notices(lambda: invsss.load_pair(*pair_files(tmp_path, grey_source, colour)))
    assert (pair.source.shape, pair.target.shape) == ((H, W, 3), (H, W, 3))
    assert not any("identical" in n for n in notes)
    # A one-channel source and a grey target stored as RGB (refused before: 1 against 3 channels).
    grey_one = tmp_path / "grey_one.exr"
    invsss.write_image(grey_one, grey_image(7))
    pair, _ = notices(lambda: invsss.load_pair(*pair_files(tmp_path, grey_one, three)))
    assert (pair.source.shape, pair.target.shape) == ((H, W, 1), (H, W, 1))


def test_a_jpeg_grey_may_differ_by_one_code_a_png_grey_not_at_all():
    """The tolerances themselves: a decoder that rounds each channel on its own may put a
    JPEG's grey one code apart (libjpeg does not; see JPEG_GREY_CODES)."""
    from invsss.io.images import is_grey_rgb
    from invsss.io.rasters import Raster

    codes = np.repeat(np.arange(H * W, dtype=np.int64).reshape(H, W, 1) % 250, 3, axis=2)
    codes[3, 4, 1] += 1
    assert is_grey_rgb(Raster(codes.astype(np.uint8), "srgb", "jpeg"))
    assert not is_grey_rgb(Raster(codes.astype(np.uint8), "srgb", "png"))
    codes[3, 4, 1] += 1
    assert not is_grey_rgb(Raster(codes.astype(np.uint8), "srgb", "jpeg"))
