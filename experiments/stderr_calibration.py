"""Are the standard errors honest? Monte Carlo over noise draws (issue 13).

A model-made pair's noise-free target is photographed again and again with fresh
noise (``photo_robustness``'s sensor rows: the pair's white Gaussian noise, 8-bit
sRGB JPEG q90 of it, or Poisson-Gaussian shot noise), each photograph fitted as the
bundled pair is (no registration), and the scatter of the estimates over the draws
is set against the standard error the fits report. Honest errors give a ratio
(scatter / mean reported error) near 1; with few draws the scatter itself is
uncertain by about 1 / sqrt(2 (draws - 1)).

``--variants`` fits every photograph in more than one way, so that a bias of one
way of fitting shows against another on the same draws (the paired difference's
scatter is much smaller than either's): ``plain`` (no registration), ``rim``
(plain, with the comparison cut ``ALIGN_RIM_PX`` inside the mask as an aligned
fit cuts it), ``vignetting``, ``similarity`` (registered), and ``+``-joined
combinations such as ``similarity+vignetting``::

    python experiments/stderr_calibration.py [--pair data_synthetic/fran_front] [--draws 12]
        [--rows white,jpeg90,shot] [--starts 2] [--seed 21] [--block-px 8]
        [--variants plain,similarity+vignetting]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import invsss
from scipy import ndimage

from invsss.estimator.stages import alignment as alignment_stage
from invsss.estimator import uncertainty
from make_synthetic import CameraMove
from photo_robustness import Row, clean_target, photograph

ROWS = {"white": Row(), "jpeg90": Row(sensor="jpeg"), "shot": Row(sensor="shot")}
NAMES = ("sss_level", "correction")
ALIGNS = ("translation", "similarity", "affine")


def fit_variant(variant: str, pair, photo, level, starts: int):
    """``photo`` fitted against ``pair`` the way ``variant`` names (see the module docstring)."""
    parts = set(variant.split("+"))
    unknown = parts - {"plain", "rim", "vignetting", *ALIGNS}
    if unknown:
        raise SystemExit(f"--variants: unknown part(s) {sorted(unknown)}; expected plain, rim, vignetting, "
                         f"or one of {ALIGNS}")
    align = next((a for a in ALIGNS if a in parts), "none")
    if "rim" in parts:
        inner = ndimage.binary_erosion(np.asarray(pair.mask) > 0, iterations=alignment_stage.ALIGN_RIM_PX)
        item = invsss.ImagePair(pair.source, photo, pair.depth, pair.mask, fit_weight=inner.astype(np.float64))
        return invsss.fit_pairs([item], n_starts=starts, saturation=level, align=align,
                                vignetting="vignetting" in parts)
    return invsss.fit_pair(pair.source, photo, pair.depth, pair.mask, n_starts=starts, saturation=level,
                           align=align, vignetting="vignetting" in parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pair", type=Path, default=Path("data_synthetic/fran_front"))
    parser.add_argument("--draws", type=int, default=12)
    parser.add_argument("--rows", default=",".join(ROWS))
    parser.add_argument("--starts", type=int, default=2)
    parser.add_argument("--seed", type=int, default=21)
    parser.add_argument("--block-px", type=int, default=uncertainty.BLOCK_PX,
                        help="side of the blocks within which the covariance lets the noise correlate "
                        f"(default {uncertainty.BLOCK_PX}; 1 takes the noise as white, as before issue 13)")
    parser.add_argument("--variants", default="plain",
                        help="comma-separated ways to fit each photograph (default plain; see above)")
    args = parser.parse_args()
    uncertainty.BLOCK_PX = args.block_px
    if not (args.pair / "truth.json").is_file():
        parser.error(f"--pair: {args.pair} has no truth.json (a model-made pair is needed)")
    pair = invsss.load_pair(*(args.pair / f for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    clean, sigma = clean_target(args.pair, pair, CameraMove(), "camera")
    rng = np.random.default_rng(args.seed)
    variants = args.variants.split(",")
    lines, differences = [], []
    for name in args.rows.split(","):
        values = {v: {k: [] for k in NAMES} for v in variants}
        errors = {v: {k: [] for k in NAMES} for v in variants}
        started = time.perf_counter()
        for draw in range(args.draws):
            photo, level = photograph(clean, sigma, ROWS[name], rng)
            photo = photo.astype(np.float32)
            photo = photo[..., 0] if np.ndim(pair.target) == 2 else photo
            for variant in variants:
                fit = fit_variant(variant, pair, photo, level, args.starts)
                for k in NAMES:
                    values[variant][k].append(float(fit.values[k]))
                    errors[variant][k].append(float(fit.stderr[k]) if fit.stderr.get(k) is not None else np.nan)
                print(f"  {name} draw {draw + 1}/{args.draws} {variant}: " + ", ".join(
                    f"{k} {values[variant][k][-1]:.1f} +- {errors[variant][k][-1]:.1f}" for k in NAMES), flush=True)
        for variant in variants:
            cells = [name, variant, str(args.draws)]
            for k in NAMES:
                v, e = np.array(values[variant][k]), np.array(errors[variant][k])
                scatter, reported = float(np.std(v, ddof=1)), float(np.nanmean(e))
                cells += [f"{np.mean(v):.1f}", f"{scatter:.1f}", f"{reported:.1f}", f"{scatter / reported:.2f}"]
            lines.append("| " + " | ".join(cells) + " |")
            if variant != variants[0]:
                # Paired over the same photographs: the noise they share cancels.
                cells = [name, f"{variant} - {variants[0]}"]
                for k in NAMES:
                    d = np.array(values[variant][k]) - np.array(values[variants[0]][k])
                    cells += [f"{np.mean(d):+.1f} +- {np.std(d, ddof=1) / np.sqrt(len(d)):.1f}",
                              f"{np.std(d, ddof=1):.1f}"]
                differences.append("| " + " | ".join(cells) + " |")
        print(f"  {name}: {time.perf_counter() - started:.0f} s", flush=True)
    header = ("| noise | fit | draws | " + " | ".join(f"{k} mean | {k} scatter | {k} reported error | ratio"
                                                    for k in NAMES) + " |")
    print("\n" + header + "\n|" + "---|" * (header.count("|") - 1) + "\n" + "\n".join(lines))
    if differences:
        header = "| noise | difference | " + " | ".join(f"{k} mean (+- its error) | {k} scatter" for k in NAMES) + " |"
        print("\n" + header + "\n|" + "---|" * (header.count("|") - 1) + "\n" + "\n".join(differences))

if __name__ == "__main__":
    main()
