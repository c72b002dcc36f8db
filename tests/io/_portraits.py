"""Two portraits and their faces drawn by hand, for the face-mask tests
(tests/io/test_photo_mask.py, which says how they were drawn) and
experiments/photo_masks.py: the astronaut (``skimage.data.astronaut()``, NASA, public
domain) and Grace Hopper (``grace_hopper.jpg`` of matplotlib's sample data, US Navy,
public domain)."""

from __future__ import annotations

import numpy as np
from skimage.draw import polygon as fill_polygon

from invsss.io import srgb_to_linear

#: The astronaut's face, drawn by hand (row, column).
ASTRONAUT_FACE = [
    (80, 190), (77, 200), (76, 212), (77, 225), (79, 238), (82, 250), (85, 260), (92, 266), (102, 268),
    (112, 267), (120, 268), (124, 272), (130, 273), (138, 271), (143, 266), (150, 262), (158, 258),
    (165, 252), (170, 243), (172, 232), (172, 222), (170, 212), (165, 203), (158, 196), (148, 192),
    (138, 189), (134, 185), (128, 180), (120, 179), (114, 181), (108, 186), (98, 187), (88, 188),
]


def face_mask(vertices, shape, scale: float = 1.0, offset=(0.0, 0.0)) -> np.ndarray:
    """The hand-drawn polygon as a boolean mask of ``shape``; its vertices moved by
    ``-offset`` and then multiplied by ``scale`` (a crop, then a reduction)."""
    v = (np.asarray(vertices, np.float64) - np.asarray(offset)) * scale
    mask = np.zeros(shape, bool)
    rows, cols = fill_polygon(v[:, 0], v[:, 1], shape)
    mask[rows, cols] = True
    return mask


def iou(a, b) -> float:
    a, b = np.asarray(a) > 0.5, np.asarray(b) > 0.5
    return float((a & b).sum() / (a | b).sum())


def astronaut() -> np.ndarray:
    from skimage.data import astronaut as load

    return srgb_to_linear(load() / 255.0)


#: Grace Hopper's face, drawn by hand (row, column), under the hat's brim and inside the
#: white hair; the glasses are inside it.
HOPPER_FACE = [
    (150, 195), (143, 210), (140, 230), (139, 255), (139, 280), (140, 305), (145, 325), (153, 338),
    (165, 345), (180, 350), (188, 357), (200, 366), (215, 369), (230, 368), (245, 364), (258, 358),
    (268, 348), (280, 339), (292, 332), (305, 324), (316, 310), (323, 293), (326, 272), (325, 252),
    (320, 232), (310, 216), (298, 204), (285, 196), (270, 186), (262, 178), (250, 169), (230, 163),
    (210, 162), (198, 165), (190, 172), (182, 180), (170, 186), (160, 190),
]


def hopper() -> np.ndarray:
    """Grace Hopper's portrait, linear RGB."""
    from matplotlib import cbook
    from matplotlib.image import imread

    return srgb_to_linear(imread(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False)) / 255.0)
