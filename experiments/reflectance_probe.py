"""Would a multiple-scattering reflectance law for the key light close the gap? (issue 10)

The residual of the three-term fit (``--light-terms shift,grazing,incidence``) on the
path-traced faces has a broad part: the side the key light reaches is brighter in
the path tracer than in the fit, the side only the fill light reaches darker. A
Lambertian source has the wrong angular law. A semi-infinite medium of
single-scattering albedo ``w`` with isotropic scattering reflects light arriving at
``mu0 = n . l`` towards ``mu = n . v`` in proportion to (Chandrasekhar 1960,
"Radiative transfer", section 29; the H function in Hapke's 1981 approximation)::

    f(mu, mu0) = H(mu) H(mu0) / (mu + mu0),    H(x) = (1 + 2 x) / (1 + 2 x sqrt(1 - w))

times what a Lambertian surface of the same irradiance returns. The law belongs to
light arriving from one direction, so it can be applied to the key light only: a
renderer has that light's diffuse contribution on its own (its lighting pass adds
one light at a time), and so does every pair ``invsss scene`` writes (``key.exr``,
the source lit by the key light alone; ``source - key`` is the fill light's part).
This script measures, post hoc, what the law would buy:

1. it fits the pair (``shift`` alone, and all three terms);
2. it renders ``K`` (the key light's part) and ``S - K`` through the fitted model,
   and also ``K f`` (the law applied before the blur, as a renderer's lighting
   pass would);
3. it fits the target as a linear mix of such images plus an offset, by least
   squares, for each ``w``, and prints the PSNR on the mask eroded by 2 px.

``mu`` is the normal's z (a distant camera) and ``mu0`` comes from the pair's
``normal.exr`` and ``light.exr``::

    python experiments/reflectance_probe.py [data_synthetic/pt_face_940 ...]

``--joint`` fits instead (the estimator, with the ``shift`` term or ``--terms``) the source the
term would give, ``K f(mu, mu0) / f(1, 1) + rho (S - K)``, on a grid of ``w`` and
the fill's relative gain ``rho``, and scores it as ``experiments/fidelity.py``
does; then it carries each view's best fit (``w``, ``rho`` and the fitted
parameters) to the other view of the same medium, as fidelity.py's transfer rows do.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import ndimage

import invsss

ALBEDOS = (0.9, 0.95, 0.965, 0.98, 0.99, 0.995)


def chandrasekhar(mu, w):
    """Hapke's approximation to Chandrasekhar's H function for isotropic scattering."""
    return (1.0 + 2.0 * mu) / (1.0 + 2.0 * mu * np.sqrt(1.0 - w))


def cosines(normal, light):
    """``(mu, mu0)``, each (H, W, 1): ``n_z`` (a distant camera) and ``clip(n . l, 0, 1)``."""
    mu = np.clip(normal[..., 2], 1e-3, 1.0)[..., None]
    mu0 = np.clip(np.sum(normal * light, axis=-1), 0.0, 1.0)[..., None]
    return mu, mu0


def mixed_psnr(target, keep, columns) -> float:
    """PSNR on ``keep`` (peak: the target's maximum there) of the least-squares mix of
    ``columns`` (images broadcast to the target's shape) and an offset that best fits ``target``."""
    wanted = target[keep].ravel()
    design = np.stack([np.broadcast_to(c, target.shape)[keep].ravel() for c in columns]
                      + [np.ones_like(wanted)], axis=1)
    coef, *_ = np.linalg.lstsq(design, wanted, rcond=None)
    return 10.0 * np.log10(float(target[keep].max()) ** 2 / np.mean((wanted - design @ coef) ** 2))


def probe(folder: Path) -> None:
    pair = invsss.load_pair(*(folder / f for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    normal = np.asarray(invsss.read_image(folder / "normal.exr"), np.float64)
    light = np.asarray(invsss.read_image(folder / "light.exr"), np.float64)
    buffers = invsss.LightBuffers(normal, light)
    source, target = np.asarray(pair.source, np.float64), np.asarray(pair.target, np.float64)
    key = np.asarray(invsss.read_image(folder / "key.exr"), np.float64)
    keep = ndimage.binary_erosion(np.asarray(pair.mask) > 0, iterations=2)
    mu, mu0 = cosines(normal, light)

    def psnr(columns) -> float:
        return mixed_psnr(target, keep, columns)

    print(f"{folder.name}: the key light gives {key[keep].sum() / source[keep].sum():.0%} of the source on the mask")
    for terms in ("shift", "shift,grazing,incidence"):
        fit = invsss.fit_pair(pair.source, pair.target, pair.depth, pair.mask, light_terms=terms,
                              light_buffers=buffers)
        applied = fit.light_terms_params()

        def through_fit(image):
            return np.asarray(invsss.render(image, pair.depth, pair.mask, fit.params, light_terms=applied,
                                            light_buffers=buffers), np.float64).reshape(target.shape)

        whole, keyed = through_fit(source), through_fit(key)
        fill = whole - keyed
        print(f"  fit with {terms}: {psnr([whole]):.2f} dB; key and fill with gains of their own "
              f"{psnr([keyed, fill]):.2f} dB")
        for w in ALBEDOS:
            law = chandrasekhar(mu, w) * chandrasekhar(mu0, w) / (mu + mu0)
            print(f"    w {w:5.3f}: key x law, fill {psnr([keyed * law, fill]):.2f} dB | "
                  f"the same, the law before the blur {psnr([through_fit(key * law), fill]):.2f} dB | "
                  f"key x law, fill x H(mu) {psnr([keyed * law, fill * chandrasekhar(mu, w)]):.2f} dB | "
                  f"everything x law {psnr([whole * law]):.2f} dB")


JOINT_ALBEDOS = (0.9, 0.93, 0.95, 0.97)
JOINT_FILL = (0.7, 0.85, 1.0)


def law_source(source, key, normal, light, mask, w, rho):
    """The source the term would give: the key light's part under the law, normalised
    to 1 where light arrives and leaves along the normal, plus ``rho`` times the rest."""
    mu, mu0 = cosines(normal, light)
    law = chandrasekhar(mu, w) * chandrasekhar(mu0, w) / (mu + mu0) / (chandrasekhar(1.0, w) ** 2 / 2.0)
    changed = key * law + rho * (source - key)
    return np.where(mask[..., None] > 0, changed, source)


def joint(folders, albedos=JOINT_ALBEDOS, fills=JOINT_FILL, terms="shift") -> None:
    from fidelity import eroded, load_scene_pair, score

    def read(folder):
        pair = load_scene_pair(folder)
        key = invsss.read_image(folder / "key.exr").astype(np.float64)
        normal, light = (np.asarray(b, np.float64) for b in (pair["buffers"].normal, pair["buffers"].light))
        return pair, key, normal, light, eroded(pair["mask"], 2)

    loaded = {folder: read(folder) for folder in folders}
    best = {}
    for folder in folders:
        pair, key, normal, light, mask = loaded[folder]
        plain = invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"], light_terms=terms,
                                light_buffers=pair["buffers"])
        print(f"{folder.name}: fit + {terms} {score(plain.fitted[0], pair, mask)['psnr']:.2f} dB")
        for w in albedos:
            row = []
            for rho in fills:
                changed = law_source(pair["source"], key, normal, light, pair["mask"], w, rho)
                fit = invsss.fit_pair(changed, pair["target"], pair["depth"], pair["mask"], light_terms=terms,
                                      light_buffers=pair["buffers"])
                psnr = score(fit.fitted[0], pair, mask)["psnr"]
                row.append(f"rho {rho}: {psnr:.2f}")
                if psnr > best.get(folder, (-np.inf,))[0]:
                    best[folder] = (psnr, w, rho, fit)
            print(f"  w {w}: " + " | ".join(row) + " dB")
        psnr, w, rho, fit = best[folder]
        print(f"  best: {psnr:.2f} dB at w {w}, rho {rho}; kappa {fit.light_terms.get('shift'):.2f} mm, "
              f"sss_level {float(fit.params.sss_level):.0f}")
    # Carried to the other view of the same medium.
    for a in folders:
        for b in folders:
            if a == b or loaded[a][0]["info"]["medium"] != loaded[b][0]["info"]["medium"]:
                continue
            _, w, rho, fit = best[a]
            pair, key, normal, light, mask = loaded[b]
            changed = law_source(pair["source"], key, normal, light, pair["mask"], w, rho)
            prediction = invsss.render(changed, pair["depth"], pair["mask"], fit.params,
                                       light_terms=fit.light_terms_params(), light_buffers=pair["buffers"])
            carried = score(np.asarray(prediction), pair, mask)["psnr"]
            print(f"{a.name} -> {b.name}: {carried:.2f} dB against {best[b][0]:.2f} dB for its own fit "
                  f"({carried - best[b][0]:+.2f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--joint", action="store_true", help="fit the law's source on a grid (see above)")
    parser.add_argument("--albedos", type=float, nargs="+", default=JOINT_ALBEDOS, help="--joint: the grid of w")
    parser.add_argument("--fill", type=float, nargs="+", default=JOINT_FILL, help="--joint: the grid of rho")
    parser.add_argument("--terms", default="shift", help="--joint: the light terms fitted with the law (default shift)")
    parser.add_argument("pairs", nargs="*", type=Path,
                        default=[Path("data_synthetic") / n for n in ("pt_face_940", "pt_face_940_turned",
                                                                       "pt_face_skin1")])
    args = parser.parse_args()
    for folder in args.pairs:
        if not (folder / "key.exr").is_file():
            parser.error(f"{folder}: no key.exr (a path-traced pair written by invsss scene is needed)")
    if args.joint:
        joint(args.pairs, args.albedos, args.fill, args.terms)
        return
    for folder in args.pairs:
        probe(folder)


if __name__ == "__main__":
    main()
