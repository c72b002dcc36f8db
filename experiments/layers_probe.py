"""What would an extra image layer beside the blur buy? (issue 29, item 5: the gap's shape)

The best term set (``shift,law``) leaves 5-6 dB between the fit and the noise
ceiling on the tuning pairs, most of it fine detail near edges. The law changes the
key light's part before the blur, so light that scattered once (sharp, with
Lommel-Seeliger's angular law ``1 / (mu + mu0)``) and light that scattered many
times (broad, ``H(mu) H(mu0) / (mu + mu0)``) share one profile. This script asks,
post hoc, whether a layer that skips the blur would help: it fits the pair with
``--light-terms shift,law``, renders the prediction ``P``, and fits the target as a
least-squares mix of ``P``, an offset and each candidate layer, printing the PSNR on
the mask eroded by 2 px (as ``experiments/fidelity.py`` scores). A layer's gain here
is what a joint fit could at least start from; a layer that gains little post hoc is
not worth building.

Candidate layers (``K`` the key light's part, ``t`` the law's fade, section 8 of
docs/model.md):

* ``single``: ``t K / (mu + mu0)``, single scattering relative to Lambert, unblurred;
* ``key``: ``K``, the key light's part unblurred (a sharp Lambertian component);
* ``fill``: ``S - K``, the other lights' part unblurred;
* ``single blurred``: ``single`` through the fitted blur;

Run it on tuning pairs only (data_synthetic/SPLIT.toml)::

    python experiments/layers_probe.py data_synthetic/pt_face_940 ...
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

import invsss

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from fidelity import eroded, load_scene_pair  # noqa: E402


def cosines(normal, light):
    mu = np.clip(normal[..., 2], 0.0, 1.0)[..., None]
    mu0 = np.clip(np.sum(normal * light, axis=-1), 0.0, 1.0)[..., None]
    fade = np.clip(np.minimum(mu, mu0) / 0.1, 0.0, 1.0)
    return mu, mu0, fade


def probe(folder: pathlib.Path, terms: str) -> None:
    pair = load_scene_pair(folder)
    source, target = (np.asarray(pair[k], np.float64) for k in ("source", "target"))
    key = np.asarray(pair["buffers"].key, np.float64)
    normal, light = (np.asarray(b, np.float64) for b in (pair["buffers"].normal, pair["buffers"].light))
    keep = eroded(pair["mask"], 2) > 0
    peak = float(target[keep].max())
    mu, mu0, fade = cosines(normal, light)

    def psnr(columns) -> float:
        wanted = target[keep].ravel()
        design = np.stack([np.broadcast_to(c, target.shape)[keep].ravel() for c in columns]
                          + [np.ones_like(wanted)], axis=1)
        coef, *_ = np.linalg.lstsq(design, wanted, rcond=None)
        return 10.0 * np.log10(peak**2 / np.mean((wanted - design @ coef) ** 2))

    fit = invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"], light_terms=terms,
                          light_buffers=pair["buffers"])
    prediction = np.asarray(fit.fitted[0], np.float64).reshape(target.shape)
    single = fade * key / np.maximum(mu + mu0, 1e-3)

    def blurred(image):
        return np.asarray(invsss.render(image.astype(np.float32), pair["depth"], pair["mask"], fit.params),
                          np.float64).reshape(target.shape)

    base = psnr([prediction])
    rows = {"single": [single], "key": [key], "fill": [source - key], "single blurred": [blurred(single)],
            "single + key": [single, key], "single + key + fill": [single, key, source - key]}
    cells = " | ".join(f"{name} {psnr([prediction, *layers]) - base:+.2f}" for name, layers in rows.items())
    print(f"{folder.name}: fit + {terms} {base:.2f} dB (noise ceiling "
          f"{pair['info']['noise']['noise_ceiling_db']:.2f}); with a layer: {cells}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--terms", default="shift,law", help="the light terms of the fit (default shift,law)")
    parser.add_argument("pairs", nargs="+", type=pathlib.Path)
    args = parser.parse_args()
    for folder in args.pairs:
        probe(folder, args.terms)


if __name__ == "__main__":
    main()
