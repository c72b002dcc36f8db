"""Masks stored with codes 0 and 1 and grey photographs stored as three identical
channels, as files, for the tests of how they are read (issue 30, cases 1 and 2)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import OpenImageIO as oiio
import pytest

import invsss
from invsss.io import linear_to_srgb
from tests import ROOT

H, W = 12, 16
FRAN = str(ROOT / "data_synthetic" / "fran_front")


def write_codes(path, codes, pixel_type, **attributes):
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


def notices(func):
    """``func()``'s result and the messages of the InputNotices it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = func()
    return value, [str(w.message) for w in caught if issubclass(w.category, invsss.InputNotice)]


def skin_rect():
    """A rectangle of skin in an H x W frame."""
    skin = np.zeros((H, W), bool)
    skin[2:10, 3:12] = True
    return skin


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
    write_codes(paths["mask"], skin_rect().astype(np.uint8) * 255, "uint8")
    write_codes(paths["mask01"], skin_rect().astype(np.uint8), "uint8")
    paths["params"].write_text(json.dumps({"sss_level": 600.0, "correction": 300.0, "maxdd": 0.02,
                                           "weights": [0.4, 0.6], "variances": [0.3, 1.5]}))
    return paths


def grey_image(seed=4):
    """A random grey image, H x W."""
    return np.random.default_rng(seed).uniform(0.05, 0.9, (H, W)).astype(np.float32)


def rgb_source(tmp_path):
    """A random colour source image file."""
    path = tmp_path / "source.exr"
    invsss.write_image(path, np.random.default_rng(5).uniform(0.1, 0.9, (H, W, 3)).astype(np.float32))
    return path


def pair_files(tmp_path, source, target):
    """``source``, ``target`` and a flat depth file and a 0/255 mask file of :func:`skin_rect`."""
    depth, mask = tmp_path / "depth.exr", tmp_path / "mask.png"
    invsss.write_image(depth, np.full((H, W), 500.0, np.float32))
    write_codes(mask, skin_rect().astype(np.uint8) * 255, "uint8")
    return source, target, depth, mask


def grey_files(tmp_path, ext):
    """The same grey written as one channel and as three identical channels."""
    grey = grey_image()
    one, three = tmp_path / f"grey1{ext}", tmp_path / f"grey3{ext}"
    if ext == ".jpg":
        # Chroma subsampled 4:2:0, as cameras write (write_image writes 4:4:4).
        codes = np.round(linear_to_srgb(grey) * 255).astype(np.uint8)
        write_codes(one, codes, "uint8", Compression="jpeg:90", jpeg_subsampling="4:2:0")
        write_codes(three, np.repeat(codes[..., None], 3, 2), "uint8", Compression="jpeg:90",
                     jpeg_subsampling="4:2:0")
    else:
        bits = {".png": 8, ".exr": 32, ".tif": 16}[ext]
        invsss.write_image(one, grey, bits=bits)
        invsss.write_image(three, np.repeat(grey[..., None], 3, 2), bits=bits)
    return one, three
