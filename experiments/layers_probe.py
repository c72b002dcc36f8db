"""What is left between the best light-term fit and the noise ceiling? (issue 29, item 5)

The best term set (``shift,law``) leaves 5-6 dB between the fit and the target's
noise ceiling on the tuning pairs. This script asks two questions of that residual,
post hoc, on pairs written by ``invsss scene``:

1. **Would another image beside the blur explain it?** It fits the pair with
   ``--light-terms shift,law``, takes the prediction ``P``, and fits the target as a
   least-squares mix of ``P``, an offset and each candidate layer, printing the PSNR
   gain on the mask eroded by 2 px (scored as ``experiments/fidelity.py`` scores). A
   joint fit could start from such a gain; a layer that gains nothing post hoc is not
   worth a term. Candidates (``K`` the key light's part, ``S`` the source, ``t`` the
   law's fade of docs/model.md section 8, ``mu = n_z``, ``mu0 = n . l``):

   * ``single``: ``t K / (mu + mu0)``, single scattering relative to Lambert (its
     angular law differs from the multiply scattered light's, which the law gives),
     unblurred, and ``single blurred`` through the fitted blur;
   * ``key``, ``fill``: ``K`` and ``S - K`` unblurred (a sharp component);
   * ``P x curvature``, ``K x curvature``: light leaking from convex parts (the
     divergence of the normal buffer, per mm);
   * ``key edges``: the key light's gradient magnitude (shadow edges);
   * ``P x (1 - n_z)``: the grazing gain, again;
   * ``wider blur``, ``much wider blur``: the source through the fitted blur with every
     variance 3 and 10 times larger (a profile tail).

2. **How much of it is the source's own noise?** The noise ceiling takes the
   prediction to be noise-free, but the source is a Monte Carlo render too. With
   ``--source-noise`` the source is rendered again with another seed (the same scene
   file, ``seed + 1000``; about a minute at 128 px on 2 cores), the difference of the
   two renders (over the square root of 2) is put through the fitted blur and gain,
   and the script prints that noise, the target's, the residual's, and what is left
   of the residual once both are taken off (the model's own error, in quadrature).

Run it on tuning pairs only (data_synthetic/SPLIT.toml)::

    python experiments/layers_probe.py [--source-noise] data_synthetic/pt_face_940 ...
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys

import numpy as np

import invsss

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from fidelity import eroded, load_scene_pair, photometric_match  # noqa: E402
from reflectance_probe import mixed_psnr  # noqa: E402

SCENES = pathlib.Path(__file__).parent / "scenes"


def cosines(normal, light):
    """``(mu, mu0, t)``, each (H, W, 1): ``n_z``, ``n . l`` (both clipped to [0, 1]) and the law's fade."""
    mu = np.clip(normal[..., 2], 0.0, 1.0)[..., None]
    mu0 = np.clip(np.sum(normal * light, axis=-1), 0.0, 1.0)[..., None]
    return mu, mu0, np.clip(np.minimum(mu, mu0) / 0.1, 0.0, 1.0)


def surface_curvature(normal, depth):
    """The divergence of the normal's image-plane part, per mm up to one constant (a
    pixel's size grows with depth): positive where the surface is convex (image rows
    point down, hence the sign of y)."""
    divergence = np.gradient(normal[..., 0], axis=1) - np.gradient(normal[..., 1], axis=0)
    return (divergence / np.maximum(depth, 1e-6) * np.median(depth))[..., None]


def through_blur(image, pair, params, variance_factor=1.0):
    """``image`` through the fitted blur (variances scaled by ``variance_factor``), no light terms."""
    scaled = invsss.SSSParams(params.sss_level, params.correction, params.maxdd, params.weights,
                              np.asarray(params.variances) * variance_factor)
    out = invsss.render(np.asarray(image, np.float32), pair["depth"], pair["mask"], scaled)
    return np.asarray(out, np.float64).reshape(np.shape(image))


def layer_gains(pair, fit, keep) -> dict:
    """The PSNR gain of each candidate layer mixed with the fit's prediction (dB)."""
    source, target = (np.asarray(pair[k], np.float64) for k in ("source", "target"))
    key = np.asarray(pair["buffers"].key, np.float64)
    normal, light = (np.asarray(b, np.float64) for b in (pair["buffers"].normal, pair["buffers"].light))
    mu, mu0, fade = cosines(normal, light)
    prediction = np.asarray(fit.fitted[0], np.float64).reshape(target.shape)

    def psnr(columns) -> float:
        return mixed_psnr(target, keep, columns)

    single = fade * key / np.maximum(mu + mu0, 1e-3)
    curvature = surface_curvature(normal, np.asarray(pair["depth"], np.float64))
    edges = np.sqrt(sum(np.square(np.gradient(key[..., 0], axis=a)) for a in (0, 1)))[..., None]
    layers = {
        "single": [single], "single blurred": [through_blur(single, pair, fit.params)],
        "key": [key], "fill": [source - key], "single + key + fill": [single, key, source - key],
        "P x curvature": [prediction * curvature], "K x curvature": [key * curvature],
        "key edges": [edges], "P x (1 - n_z)": [prediction * (1.0 - mu)],
        "wider blur": [through_blur(source, pair, fit.params, 3.0)],
        "much wider blur": [through_blur(source, pair, fit.params, 10.0)],
    }
    base = psnr([prediction])
    return {"fit": base, **{name: psnr([prediction, *images]) - base for name, images in layers.items()}}


def source_noise(folder, pair, fit, keep) -> dict:
    """The source's render noise through the fitted blur and gain, beside the target's
    noise and the fit's residual (rms on ``keep``, the target's units)."""
    from invsss.scenes import load_config, render_scene

    info = json.loads((folder / "scene.json").read_text())
    scene_file = SCENES / f"{folder.name.removeprefix('pt_')}.toml"
    here = os.getcwd()
    os.chdir(SCENES)  # scene files name their meshes relative to themselves
    try:
        config = load_config(scene_file.name)
        again = render_scene(config.model_copy(update={"seed": config.seed + 1000}), target=False)
    finally:
        os.chdir(here)
    source = np.asarray(pair["source"], np.float64)
    noise = (source - np.asarray(again.source, np.float64).reshape(source.shape)) / np.sqrt(2.0)
    # The fit's photometric gain, from the prediction against the blurred source.
    gain = photometric_gain(np.asarray(fit.fitted[0], np.float64).reshape(source.shape[:2] + (-1,)),
                            through_blur(source, pair, fit.params), keep)
    blurred_noise = gain * through_blur(noise, pair, fit.params)
    matched = photometric_match(np.asarray(fit.fitted[0], np.float32), pair["target"], keep.astype(np.float32))
    residual = np.asarray(pair["target"], np.float64) - matched

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x[keep]))))

    found = {"target noise": float(info["noise"]["noise_rms"]), "source noise, blurred": rms(blurred_noise),
             "residual": rms(residual)}
    left = found["residual"] ** 2 - found["target noise"] ** 2 - found["source noise, blurred"] ** 2
    found["model error"] = float(np.sqrt(max(left, 0.0)))
    found["ceiling"] = float(
        info["noise"]["noise_ceiling_db"]
        - 10.0 * np.log10(1.0 + (found["source noise, blurred"] / found["target noise"]) ** 2))
    return found


def photometric_gain(prediction, blurred, keep) -> float:
    """The least-squares gain from ``blurred`` to ``prediction`` on ``keep`` (with an offset)."""
    p, b = prediction[keep].ravel(), blurred[keep].ravel()
    design = np.stack([b, np.ones_like(b)], axis=1)
    (gain, _), *_ = np.linalg.lstsq(design, p, rcond=None)
    return float(gain)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--terms", default="shift,law", help="the light terms of the fit (default shift,law)")
    parser.add_argument("--source-noise", action="store_true",
                        help="render each source again with another seed and measure its noise (slow)")
    parser.add_argument("pairs", nargs="+", type=pathlib.Path)
    args = parser.parse_args()
    for folder in args.pairs:
        pair = load_scene_pair(folder)
        keep = eroded(pair["mask"], 2) > 0
        fit = invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"],
                              light_terms=args.terms, light_buffers=pair["buffers"])
        gains = layer_gains(pair, fit, keep)
        cells = " | ".join(f"{name} {gain:+.2f}" for name, gain in gains.items() if name != "fit")
        print(f"{folder.name}: fit + {args.terms} {gains['fit']:.2f} dB (noise ceiling "
              f"{pair['info']['noise']['noise_ceiling_db']:.2f}); gain with a layer: {cells}", flush=True)
        if args.source_noise:
            found = source_noise(folder, pair, fit, keep)
            print("  rms: " + ", ".join(f"{name} {value:.4f}" for name, value in found.items()
                                        if name != "ceiling")
                  + f"; the noise ceiling with the source's noise {found['ceiling']:.2f} dB",
                  flush=True)


if __name__ == "__main__":
    main()
