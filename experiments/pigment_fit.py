"""What the pigment field buys on the photo route (issue 47): a table.

Two channel or wavelength pairs, each fitted with one Gaussian (the photo route's
default) at one distance, with the pigment field off and at degrees 1 and 2
(``invsss.estimator.pigment``):

``twowave`` (the degree was chosen on it)
    the bundled path-traced pair ``data_synthetic/twowave_face``: the 940 nm target
    against the visible target, the scene's mask, ``distance`` 600 mm. The render
    route's extra blur there is ``sigma_extra`` 1.090 mm (docs/capture.md, measured
    on the clean renders with the distance), 0.66 px at its 1.65 mm a pixel.
``portrait`` (held out)
    a real photograph, scikit-image's ``astronaut`` (NASA, public domain), cropped to
    the face (200 x 200, a hand-drawn ellipse as the mask): the red channel against
    the green one, decoded from sRGB.

Printed per row: the PSNR with and without the field (the same fit with the field
set to 1), the blur's width in pixels and in mm (f = 363 px for twowave, from its
scene.json), ``sss_level`` and the field's largest coefficient::

    python experiments/pigment_fit.py [--starts 2]
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

import invsss
from invsss.io.colour import srgb_to_linear
from invsss.io.photo_pair import constant_depth

ROOT = Path(__file__).resolve().parents[1]


def twowave():
    folder = ROOT / "data_synthetic" / "twowave_face"
    source = invsss.read_image(folder / "visible" / "target.exr")
    target = invsss.read_image(folder / "nir" / "target.exr")
    mask = invsss.read_mask(folder / "nir" / "mask.png")
    focal = json.loads((folder / "nir" / "scene.json").read_text())["focal_px"]
    return source, target, mask, focal


def portrait():
    from skimage import data

    rgb = srgb_to_linear(data.astronaut()[30:230, 120:320].astype(np.float64) / 255.0)
    yy, xx = np.mgrid[0:200, 0:200]
    mask = (((xx - 102) / 45.0) ** 2 + ((yy - 95) / 58.0) ** 2 <= 1.0).astype(np.float64)
    return rgb[..., 1], rgb[..., 0], mask, None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=2)
    args = parser.parse_args()
    print("| pair | split | pigment | PSNR (dB) | PSNR without the field | blur (px) | blur (mm) | sss_level | max abs a |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, split, load in (("twowave", "tuning", twowave), ("portrait", "held-out", portrait)):
        source, target, mask, focal = load()
        depth = constant_depth(mask.shape, 600.0)
        for degree in (0, 1, 2):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                r = invsss.fit_pair(source, target, depth, mask, profile="single", fix={"correction": 0.0, "maxdd": 1.0},
                                    n_starts=args.starts, pigment=degree, focal_px=focal)
            blur = r.blur
            px = f"{blur['sigma_px'][0]:.3f} ± {blur['stderr_px'][0] or float('nan'):.3f}"
            mm = "-" if focal is None else f"{blur['sigma_mm'][0]:.3f}"
            without = "-" if r.pigment is None else f"{r.pigment['psnr_without']:.2f}"
            largest = "-" if r.pigment is None else f"{np.max(np.abs(r.pigment['coefficients'])):.3f}"
            level = r.values["sss_level"]
            err = r.stderr["sss_level"]
            print(f"| {name} | {split} | {degree} | {r.psnr:.2f} | {without} | {px} | {mm} | "
                  f"{level:.1f} ± {err if err is None else round(err, 1)} | {largest} |", flush=True)


if __name__ == "__main__":
    main()
