"""How do the nuisances of a real photograph move a fit? (issue 13)

A capture simulator turns a bundled pair's target into a "photograph" with one
nuisance at a time: misregistration (shift, rotation, scale about the image
centre), vignetting (a radial gain falling to ``1 - v`` at the corners), 8-bit
sRGB JPEG, Poisson-Gaussian noise. As in a camera, the noise comes after the
optics: for a model-made pair (one with ``truth.json``) the noise-free target is
rebuilt from its truth, moved or shaded, and only then given fresh noise of the
recorded size (the ``noise`` row: Poisson-Gaussian instead; ``jpeg90`` encodes the
noisy image).

The misregistration itself is simulated by a cubic-spline resampling of the
noise-free target, which smooths it a little; a continuous-optics simulator (render
the misregistered view) would be cleaner. Each is fitted with ``align="none"`` and with
registration (``--align``); the table gives sss_level, correction and PSNR of each
fit and its change from the clean fit::

    python experiments/photo_robustness.py [--pair data_synthetic/fran_front] [--align similarity]
        [--rows clean,shift1,...] [--starts 2]

Rows: ``clean``, ``shift1``, ``shift2``, ``shift4`` (pixels, diagonal split as
(0.6, 0.8) of the length), ``rot1`` (1 degree), ``rot2s`` (2 degrees and scale
1.02), ``jpeg90``, ``noise`` (2000 electrons at the 99th percentile plus 2 e-
read noise), ``vignette20`` (20 % at the corners).
"""

from __future__ import annotations

import argparse
import io
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

import json

import invsss
from invsss.io import PARAMS_KEYS, linear_to_srgb, srgb_to_linear


def misregister(image: np.ndarray, shift=(0.0, 0.0), rotation_deg: float = 0.0, scale: float = 1.0) -> np.ndarray:
    """The photograph of a camera moved against the render: the image resampled (cubic) about its centre."""
    h, w = image.shape[:2]
    centre = np.array([(h - 1) / 2.0, (w - 1) / 2.0])
    a = np.radians(rotation_deg)
    # Output pixel y shows input position A^-1 (y - c - t) + c.
    forward = scale * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    inverse = np.linalg.inv(forward)
    offset = centre - inverse @ (centre + np.asarray(shift, np.float64))
    return np.stack([ndimage.affine_transform(image[..., c], inverse, offset=offset, order=3, mode="nearest")
                     for c in range(image.shape[-1])], axis=-1)


def vignette(image: np.ndarray, strength: float) -> np.ndarray:
    """A radial gain ``1 - strength r^2`` with r = 1 at the corners."""
    h, w = image.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    r2 = ((y - (h - 1) / 2) ** 2 + (x - (w - 1) / 2) ** 2) / (((h - 1) / 2) ** 2 + ((w - 1) / 2) ** 2)
    return image * (1.0 - strength * r2)[..., None]


def jpeg(image: np.ndarray, quality: int) -> np.ndarray:
    """8-bit sRGB JPEG at ``quality``, decoded back to linear (exposed so the 99.5th percentile is 0.9)."""
    from PIL import Image

    scale = 0.9 / np.percentile(image, 99.5)
    codes = np.round(255 * linear_to_srgb(np.clip(image * scale, 0, 1))).astype(np.uint8)
    buffer = io.BytesIO()
    mode_image = Image.fromarray(codes[..., 0] if codes.shape[-1] == 1 else codes)
    mode_image.save(buffer, format="JPEG", quality=quality)
    decoded = np.asarray(Image.open(io.BytesIO(buffer.getvalue())), np.float64) / 255.0
    decoded = decoded[..., None] if decoded.ndim == 2 else decoded
    return srgb_to_linear(decoded) / scale


def shot_noise(image: np.ndarray, electrons: float, read: float, rng) -> np.ndarray:
    """Poisson photon noise with ``electrons`` at the 99th percentile, plus Gaussian read noise (e-)."""
    per_unit = electrons / np.percentile(image, 99)
    counts = rng.poisson(np.clip(image, 0, None) * per_unit) + rng.normal(0.0, read, image.shape)
    return counts / per_unit


#: name -> (what the optics do to the noise-free image, what the sensor adds; None: Gaussian noise)
ROWS = {
    "clean": (lambda t: t, None),
    "shift1": (lambda t: misregister(t, (0.6, 0.8)), None),
    "shift2": (lambda t: misregister(t, (1.2, 1.6)), None),
    "shift4": (lambda t: misregister(t, (2.4, 3.2)), None),
    "rot1": (lambda t: misregister(t, rotation_deg=1.0), None),
    "rot2s": (lambda t: misregister(t, rotation_deg=2.0, scale=1.02), None),
    "jpeg90": (lambda t: t, "jpeg"),
    "noise": (lambda t: t, "shot"),
    "vignette20": (lambda t: vignette(t, 0.2), None),
}


def clean_target(folder: Path, pair) -> tuple[np.ndarray, float]:
    """The noise-free target of a model-made pair and its noise sigma (else the target and 0)."""
    target = np.asarray(pair.target, np.float64)
    target = target[..., None] if target.ndim == 2 else target
    truth_path = folder / "truth.json"
    if not truth_path.is_file():
        return target, 0.0
    truth = json.loads(truth_path.read_text())
    params = invsss.SSSParams.from_dict({k: truth[k] for k in PARAMS_KEYS})
    out = np.asarray(invsss.render(pair.source, pair.depth, pair.mask, params, truth["model"],
                                   tap_weights=truth["tap_weights"]), np.float64)
    if truth["channels_mix"] is not None:
        out = out @ np.asarray(truth["channels_mix"])[:, None]
    return np.asarray(truth["gain"]) * out + np.asarray(truth["offset"]), float(truth["noise_sigma"])


def photograph(clean: np.ndarray, sigma: float, name: str, rng) -> np.ndarray:
    optics, sensor = ROWS[name]
    image = optics(clean)
    if sensor == "shot":
        return shot_noise(image, 2000.0, 2.0, rng)
    image = image + sigma * rng.standard_normal(image.shape)
    return jpeg(image, 90) if sensor == "jpeg" else image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pair", type=Path, default=Path("data_synthetic/fran_front"))
    parser.add_argument("--align", default="similarity", choices=("translation", "similarity", "affine"))
    parser.add_argument("--rows", default=",".join(ROWS), help="comma-separated rows (default: all)")
    parser.add_argument("--starts", type=int, default=2)
    args = parser.parse_args()
    pair = invsss.load_pair(*(args.pair / f for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    clean_image, sigma = clean_target(args.pair, pair)
    rng = np.random.default_rng(13)
    print(f"{args.pair}: fits with {args.starts} starts; align none | align {args.align}", flush=True)
    header = ("| nuisance | sss_level | correction | PSNR dB | sss_level aligned | correction aligned "
              "| PSNR aligned | warp found |")
    rows, clean = [], {}
    for name in args.rows.split(","):
        photo = photograph(clean_image, sigma, name, rng).astype(np.float32)
        photo = photo[..., 0] if np.ndim(pair.target) == 2 else photo
        cells = [name]
        for align in ("none", args.align):
            started = time.perf_counter()
            fit = invsss.fit_pair(pair.source, photo, pair.depth, pair.mask, n_starts=args.starts, align=align)
            level, correction = float(fit.params.sss_level), float(fit.params.correction)
            level_se = fit.stderr.get("sss_level")
            if name == "clean":
                clean[align] = (level, correction, fit.psnr)
            ref = clean.get(align, (level, correction, fit.psnr))
            se = f" +- {float(level_se):.0f}" if level_se is not None else ""
            cells += [f"{level:.0f}{se} ({100 * (level / ref[0] - 1):+.0f} %)",
                      f"{correction:.0f} ({100 * (correction / ref[1] - 1):+.0f} %)" if ref[1] else f"{correction:.0f}",
                      f"{fit.psnr:.1f}"]
            if align != "none":
                a = fit.alignment[0]
                found = f"({a['shift_px'][0]:+.2f}, {a['shift_px'][1]:+.2f}) px"
                if "rotation_deg" in a:
                    found += f", {a['rotation_deg']:+.2f} deg, x{a['scale']:.3f}"
                cells.append(found)
            print(f"  {name} align={align}: {time.perf_counter() - started:.0f} s", flush=True)
        rows.append("| " + " | ".join(cells) + " |")
    print("\n" + header + "\n|---|---|---|---|---|---|---|---|\n" + "\n".join(rows))


if __name__ == "__main__":
    main()
