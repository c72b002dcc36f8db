"""How far is what Unity HDRP draws from the ``burley`` fit's image? (issue 46)

For each path-traced pair (``data_synthetic/pt_*``, both parts of SPLIT.toml, printed
part by part) this fits the ``burley`` model as an engine would use it (each channel's
``d`` free, ``sss_level`` held at the camera's focal length in pixels, scene.json's
``focal_px``; the depth is in mm), renders the fit's own image (``invsss.render``,
its fixed 32-sample pattern) and the image HDRP's pass would draw with the same
``d`` (:func:`invsss.forward.hdrp_screen_space.render_hdrp_like`) at each quality
level, and prints, on the skin mask eroded by ``--erode`` pixels (as
``experiments/fidelity.py`` scores):

``samples``
    the median over the mask of the samples HDRP takes per pixel (its footprint
    rule caps the budget);
``vs fit``
    PSNR of HDRP's image against the fit's image (peak: the fit image's range on
    the mask), for one frame and for the mean of ``--frames`` frames (each frame
    its own per-pixel rotation: what temporal anti-aliasing could at best reach);
``vs target``
    PSNR against the path-traced target, both images mapped by the fit's own gain
    and offset (the engine gets no new ones), one frame and the frame mean;
``fit vs target``
    the fit's image against the target (the fit's PSNR on this mask).

The quality levels are HDRP's: Low, Medium, High (budgets 20, 40, 80) and Max
(budget 1000, samples beyond the tile's cache read from an image downsampled by 4 per
axis, as the current sources do), plus ``max-full`` (budget 1000 at full resolution,
Max in the earlier versions with a budget).

The pairs are used at their bundled size (128 x 128): nothing is cropped or
downsampled. One ``burley`` fit per pair (about 5 s on 2 cores) and the renders take
under two minutes for the 14 pairs. ``--scale 2`` draws the fitted parameters on the
pairs upsampled twice (``sss_level`` doubled: the same face on a finer screen, where
the budgets bind); with ``--frames 4`` it took three and a half minutes.

    python experiments/engine_gap.py [PAIR_DIR ...] [--frames 16] [--scale 1] [--erode 2] [--json runs/engine_gap.json]
"""

from __future__ import annotations

import argparse
import datetime
import json
import pathlib
import sys
import time

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import invsss  # noqa: E402
from invsss.estimator.diagnostics import masked_psnr  # noqa: E402
from invsss.forward.hdrp_screen_space import QUALITY_LEVELS, render_hdrp_like, sample_counts  # noqa: E402
from invsss.scenes.split import SPLITS, pair_split, read_split  # noqa: E402

from fidelity import SPLIT_FILE, eroded, load_scene_pair  # noqa: E402

#: The rows per pair: (label, budget, downsample steps).
QUALITIES = tuple((name, *QUALITY_LEVELS[name]) for name in ("low", "medium", "high", "max")) + (
    ("max-full", QUALITY_LEVELS["max"][0], 0),
)
COLUMNS = ("pair", "split", "d (mm)", "quality", "budget", "samples", "vs fit 1f", "vs fit Nf",
           "vs target 1f", "vs target Nf", "fit vs target")


def fit_burley(pair: dict):
    """The engine's fit: ``d`` per channel free, ``sss_level`` at the focal length in pixels."""
    return invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"], model="burley",
                           gauge="sss_level", fix={"sss_level": float(pair["info"]["focal_px"])})


def to_target(image: np.ndarray, fit) -> np.ndarray:
    """``gain * image + offset`` with the fit's own gain and offset, per target channel."""
    image = image if image.ndim == 3 else image[..., None]
    return np.asarray(fit.gain) * image + np.asarray(fit.offset)


def upscaled(pair: dict, scale: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source (H s, W s, C) and depth (bilinear) and mask (nearest), ``scale`` times larger.

    The source is corrected block by block so that :func:`block_mean` gives the pair's
    source back exactly (bilinear interpolation alone softens its hard shadow edges).
    """
    source = np.asarray(pair["source"], np.float64)
    source = source if source.ndim == 3 else source[..., None]
    if scale == 1:
        return source, np.asarray(pair["depth"], np.float64), np.asarray(pair["mask"], np.float64)
    zoom = lambda a, order: ndimage.zoom(a, scale, order=order, mode="nearest", grid_mode=True)  # noqa: E731
    fine = np.stack([zoom(source[..., c], 1) for c in range(source.shape[-1])], axis=-1)
    fine += np.repeat(np.repeat(source - block_mean(fine, scale), scale, axis=0), scale, axis=1)
    return fine, zoom(np.asarray(pair["depth"], np.float64), 1), zoom(np.asarray(pair["mask"], np.float64), 0)


def block_mean(image: np.ndarray, scale: int) -> np.ndarray:
    """``image`` (H s, W s, C) averaged over blocks of ``scale x scale`` pixels: (H, W, C)."""
    h, w, c = image.shape
    return image.reshape(h // scale, scale, w // scale, scale, c).mean(axis=(1, 3))


def measure_pair(pair: dict, frames: int, erode: int, scale: int = 1) -> list[dict]:
    """The rows of one pair (one per quality level).

    With ``scale > 1`` the fitted parameters are rendered on the pair upsampled
    ``scale`` times (``sss_level`` times ``scale``: the same face on a finer screen);
    ``vs fit`` compares at that size (mask eroded ``scale`` times more), ``vs target``
    after averaging back to the pair's size.
    """
    fit = fit_burley(pair)
    d = np.sqrt(np.asarray(fit.values["variances"], np.float64))
    target = np.asarray(pair["target"], np.float64)
    if not np.allclose(to_target(np.asarray(invsss.render(pair["source"], pair["depth"], pair["mask"],
                                                          fit.params, model="burley")), fit),
                       np.asarray(fit.fitted[0]), rtol=1e-4, atol=1e-5 * np.abs(target).max()):
        raise SystemExit(f"{pair['name']}: gain * render + offset does not give the fit's image")
    # load_scene_pair filled the background's depth.
    source, depth, skin = upscaled(pair, scale)
    level = float(pair["info"]["focal_px"]) * scale
    params = invsss.SSSParams(level, 0.0, 1.0, np.ones(d.size), d**2)
    ours = np.asarray(invsss.render(source, depth, skin, params, model="burley"), np.float64)
    mask, fine_mask = eroded(pair["mask"], erode), eroded(skin, erode * scale)
    ours_t = to_target(block_mean(ours, scale), fit)
    rows = []
    for name, budget, steps in QUALITIES:
        counts = sample_counts(depth, float(np.max(d)), level, budget)
        images = [render_hdrp_like(source, depth, skin, d, level, budget=budget, downsample_steps=steps, frames=f)
                  for f in (1, frames)]
        rows.append({
            "pair": pair["name"], "split": pair["split"], "d_mm": d.tolist(), "quality": name, "scale": scale,
            "budget": budget, "downsample_steps": steps, "samples": float(np.median(counts[fine_mask > 0])),
            "vs_fit": [masked_psnr(im, ours, fine_mask) for im in images],
            "vs_target": [masked_psnr(to_target(block_mean(im, scale), fit), target, mask) for im in images],
            "fit_vs_target": masked_psnr(ours_t, target, mask),
        })
    return rows


def print_rows(rows: list[dict], frames: int) -> None:
    header = [c.replace("Nf", f"{frames}f") for c in COLUMNS]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        d = ", ".join(f"{v:.2f}" for v in r["d_mm"])
        cells = [r["pair"], r["split"], d, r["quality"], str(r["budget"]), f"{r['samples']:.0f}",
                 *(f"{v:.2f}" for v in r["vs_fit"]), *(f"{v:.2f}" for v in r["vs_target"]),
                 f"{r['fit_vs_target']:.2f}"]
        print("| " + " | ".join(cells) + " |")


def print_means(rows: list[dict], frames: int) -> None:
    """Per part and quality level: the means of the PSNR columns over the pairs that HDRP blurs."""
    print(f"\n| split | quality | pairs | vs fit 1f | vs fit {frames}f | vs target 1f | vs target {frames}f "
          "| fit vs target |")
    print("|---|---|---|---|---|---|---|---|")
    still = sorted({r["pair"] for r in rows if r["samples"] == 0})
    for part in SPLITS:
        for name, *_ in QUALITIES:
            group = [r for r in rows if r["split"] == part and r["quality"] == name and r["pair"] not in still]
            if not group:
                continue
            mean = lambda key, i=None: np.mean([r[key] if i is None else r[key][i] for r in group])  # noqa: E731
            print(f"| {part} | {name} | {len(group)} | {mean('vs_fit', 0):.2f} | {mean('vs_fit', 1):.2f} | "
                  f"{mean('vs_target', 0):.2f} | {mean('vs_target', 1):.2f} | {mean('fit_vs_target'):.2f} |")
    if still:
        print(f"\nleft out of the means (HDRP takes no samples on most of the mask, so it does not blur): "
              f"{', '.join(still)}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pairs", nargs="*", type=pathlib.Path,
                        help="pair folders (default: every pt_* folder SPLIT.toml lists)")
    parser.add_argument("--frames", type=int, default=16, help="frames averaged for the 'Nf' columns (default 16)")
    parser.add_argument("--erode", type=int, default=2, help="mask erosion in pixels (default 2)")
    parser.add_argument("--scale", type=int, default=1,
                        help="render on the pairs upsampled this many times (default 1: as bundled)")
    parser.add_argument("--json", type=pathlib.Path, help="also write the rows to this JSON file")
    args = parser.parse_args(argv)
    split = read_split(SPLIT_FILE)
    folders = args.pairs or sorted(p for p in SPLIT_FILE.parent.glob("pt_*") if p.name in split)
    started = time.perf_counter()
    rows = []
    for part in SPLITS:
        for folder in folders:
            if pair_split(folder, split) != part:
                continue
            pair = load_scene_pair(folder)
            pair["split"] = part
            began = time.perf_counter()
            rows += measure_pair(pair, args.frames, args.erode, args.scale)
            print(f"{folder.name} ({part}): {time.perf_counter() - began:.0f} s", file=sys.stderr, flush=True)
    print(f"measured {datetime.date.today().isoformat()}, {time.perf_counter() - started:.0f} s, "
          f"pairs upsampled {args.scale} times, mask eroded by {args.erode} px (of the pair's size), "
          f"frame mean over {args.frames} frames\n")
    print_rows(rows, args.frames)
    print_means(rows, args.frames)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
