"""How well the skin mask made from a pair finds the face (issue 47): photographs and
the bundled pairs.

Photographs: ``skimage.data.astronaut()`` (the one the face-aware mask was shaped on)
and matplotlib's ``grace_hopper.jpg`` (measured once, after; not used to choose
anything), each made into four pairs from the one photograph: green channel and red
channel (two bands, as visible and 940 nm are), the colour photograph and a copy blurred
by a Gaussian of 1.5 px, the colour photograph and its red channel, and the green
channel and its blurred copy (one band twice: no colour and no band ratio to tell skin
by). Reference: the faces drawn by hand in ``tests/io/_portraits.py``. Then
``skimage.data.camera()`` (a face in profile, which the frontal-face cascade should
not find). Bundled pairs: each pair's own mask, source and target as the two images
(data_synthetic/SPLIT.toml's tuning and held-out parts; the model-made pairs apart).

Prints, per pair: the rule :func:`invsss.io.skin_mask.make_skin_mask` chose, IoU, the
mask's pixels, missed and extra pixels, the IoU of the dark-background rule alone, the
notices given and the seconds taken::

    python experiments/photo_masks.py
"""

from __future__ import annotations

import importlib.util
import time
import tomllib
import warnings
from pathlib import Path

import numpy as np

import invsss
from invsss.io.skin_mask import make_skin_mask, skin_mask_from_pair

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data_synthetic"


def _tests():
    spec = importlib.util.spec_from_file_location("portraits", ROOT / "tests" / "io" / "_portraits.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _row(label, part, visible, near_infrared, truth):
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        made = make_skin_mask(visible, near_infrared)
    seconds = time.perf_counter() - start
    mask = made.mask > 0.5
    if truth is None:
        print(f"| {label} | {part} | {made.method} | - | {int(mask.sum())} | | | | {len(caught)} | {seconds:.2f} |")
        return
    bright = skin_mask_from_pair(visible, near_infrared) > 0.5
    iou = lambda a: (a & truth).sum() / (a | truth).sum()  # noqa: E731
    print(f"| {label} | {part} | {made.method} | {iou(mask):.3f} | {int(mask.sum())} | {int((truth & ~mask).sum())} "
          f"| {int((mask & ~truth).sum())} | {iou(bright):.3f} | {len(caught)} | {seconds:.2f} |")


def main() -> None:
    t = _tests()
    print("| pair | part | rule | IoU | mask pixels | missed | extra | dark-background rule's IoU | notices | s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, photo, face, part in (("astronaut", t.astronaut(), t.ASTRONAUT_FACE, "tuned on"),
                                    ("grace_hopper", t.hopper(), t.HOPPER_FACE, "held out")):
        truth = t.face_mask(face, photo.shape[:2])
        from scipy.ndimage import gaussian_filter

        pairs = {"green, red": (photo[..., 1], photo[..., 0]),
                 "colour, blurred": (photo, gaussian_filter(photo, (1.5, 1.5, 0))),
                 "colour, red": (photo, photo[..., 0]),
                 "green, blurred green": (photo[..., 1], gaussian_filter(photo[..., 1], 1.5))}
        for kind, (visible, near_infrared) in pairs.items():
            _row(f"{name} ({kind})", part, visible, near_infrared, truth)
    from scipy.ndimage import gaussian_filter
    from skimage.data import camera

    grey = invsss.io.srgb_to_linear(camera() / 255.0)
    _row("camera (grey, blurred)", "no frontal face", grey, gaussian_filter(grey, 1.5), None)
    split = tomllib.loads((DATA / "SPLIT.toml").read_text())
    parts = {**{n: "tuning" for n in split["tuning"]}, **{n: "held-out" for n in split["held-out"]}}
    for folder in sorted(p for p in DATA.iterdir() if (p / "source.exr").is_file()):
        truth = invsss.read_mask(folder / "mask.png") > 0.5
        _row(f"`{folder.name}`", parts.get(folder.name, "model-made"), invsss.read_image(folder / "source.exr"),
             invsss.read_image(folder / "target.exr"), truth)
    folder = DATA / "twowave_face"
    _row("`twowave_face` (visible and 940 nm targets)", "-", invsss.read_image(folder / "visible" / "target.exr"),
         invsss.read_image(folder / "nir" / "target.exr"), invsss.read_mask(folder / "visible" / "mask.png") > 0.5)


if __name__ == "__main__":
    main()
