"""The skin mask made from a pair (issue 33) finds the face of the bundled pairs.

Each pair's own mask is the reference: for the path-traced pairs, the pixels at least
half covered by the head (``invsss scene``); for ``leeperrysmith``, all front-facing
surface of the bust. The mask maker was tuned on the tuning pairs of
data_synthetic/SPLIT.toml only; the held-out pairs and ``leeperrysmith`` were measured
once, after (docs/capture.md, "A skin mask from the pair").

Left out, because the criterion is not meaningful there: ``pt_face_ear_backlit_940``
(IoU 0.85: 8 % of its mask gets no light at all, darker than 1 % of the image's bright
skin in both images, so no threshold can see it), ``fran_front`` and ``fran_turned``
(their masks cut out the eyes, eyebrows, nostrils and mouth by a texture rule; the mask
maker keeps the face whole) and ``flat_card`` (an ellipse drawn on a flat picture).
"""

from __future__ import annotations

import numpy as np
import pytest

import invsss
from invsss.io.skin_mask import skin_mask_from_pair
from tests import ROOT

DATA = ROOT / "data_synthetic"
TUNING = ["pt_face_940", "pt_face_940_turned", "pt_face_skin1", "pt_proc_area_940"]
HELD_OUT = ["pt_fran_dir_940", "pt_fran_dir_rough_940", "pt_proc_lowpoly_dir_940", "pt_face_rough_area_940",
            "leeperrysmith"]


def _iou(a, b) -> float:
    return float((a & b).sum() / (a | b).sum())


@pytest.mark.parametrize("name", TUNING + HELD_OUT)
def test_the_mask_made_from_the_pair_finds_the_face(name):
    folder = DATA / name
    source = invsss.read_image(folder / "source.exr")
    target = invsss.read_image(folder / "target.exr")
    truth = invsss.read_mask(folder / "mask.png") > 0.5
    made = skin_mask_from_pair(source, target)
    assert made.shape == truth.shape and set(np.unique(made)) <= {0.0, 1.0}
    assert _iou(made > 0.5, truth) > 0.95


def test_the_mask_made_from_the_two_wavelength_pair_finds_the_face():
    """The bundled pair a user with two photographs has (docs/capture.md): the visible and
    the 940 nm targets, against the scene's mask."""
    folder = DATA / "twowave_face"
    made = skin_mask_from_pair(invsss.read_image(folder / "visible" / "target.exr"),
                               invsss.read_image(folder / "nir" / "target.exr")) > 0.5
    assert _iou(made, invsss.read_mask(folder / "visible" / "mask.png") > 0.5) > 0.95


def test_a_background_bright_in_one_band_only_is_not_skin():
    """A lamp seen by the visible photograph alone stays out, and the face's shadowed
    stripe and its dark spot (a freckle, an eye) stay in."""
    rows, cols = np.mgrid[0:80, 0:80].astype(np.float64)
    face = ((rows - 40) / 30.0) ** 2 + ((cols - 36) / 24.0) ** 2 < 1.0
    shade = np.where((cols > 30) & (cols < 36), 0.15, 1.0)  # a shadow across the face
    spot = (rows - 30) ** 2 + (cols - 40) ** 2 < 9
    visible = face * shade * np.where(spot, 0.1, 0.6)
    lamp = (rows < 8) & (cols > 70)
    visible = visible + 0.8 * lamp
    nir = face * shade * 0.5
    made = skin_mask_from_pair(visible, nir) > 0.5
    assert not made[lamp].any()
    assert _iou(made, face) > 0.97


def test_images_of_different_sizes_are_refused():
    with pytest.raises(invsss.InvalidInputError, match="near-infrared photograph: expected the visible"):
        skin_mask_from_pair(np.ones((20, 20)), np.ones((20, 22)))
