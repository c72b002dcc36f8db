"""Does Hapke's approximation to Chandrasekhar's H explain the law's strength above 1?

The ``law`` term uses Hapke's closed form ``H(x) = (1 + 2x) / (1 + 2x sqrt(1 - w))``
(docs/model.md, section 8). On the path-traced procedural heads the fitted strength of
the law comes out at 1.4-1.9: the data want more angular contrast than the law gives.
This probe fits a pair's shift + law again with the exact H of isotropic scattering
(Chandrasekhar 1960, section 29: ``1 / H(x) = 1 - (w / 2) x integral_0^1 H(y) / (x + y) dy``,
solved by fixed-point iteration on 32 Gauss-Legendre nodes and evaluated elsewhere
with the same quadrature; for w <= 0.99 it agrees to 1e-4 with 96 nodes and 5 000
iterations, while at w = 1 the iteration converges slowly: H(1) = 2.893 against the
tabulated 2.9078), and prints the PSNR, the albedo and the strength of both.
Use it on tuning pairs only (data_synthetic/SPLIT.toml).

Usage::

    python experiments/exact_h_probe.py data_synthetic/pt_proc_area_940

Each law is fitted in a process of its own with the compilation cache off, since a
compiled fit would otherwise keep the law it was traced with.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import subprocess
import sys

import numpy as np

NODES, QUADRATURE = np.polynomial.legendre.leggauss(32)
ITERATIONS = 300


def exact_h(x, albedo):
    """Chandrasekhar's H for isotropic scattering of single-scattering albedo ``albedo``,
    at ``x`` (any shape); JAX, differentiable in both."""
    import jax
    import jax.numpy as jnp

    mu = jnp.asarray(0.5 * (NODES + 1.0))
    c = jnp.asarray(0.5 * QUADRATURE)
    w = jnp.reshape(jnp.asarray(albedo), (-1,))[0]

    def step(_, h):
        integral = jnp.sum(c * h[None, :] / (mu[:, None] + mu[None, :]), axis=-1)
        return 1.0 / (1.0 - 0.5 * w * mu * integral)

    h = jax.lax.fori_loop(0, ITERATIONS, step, jnp.ones_like(mu))
    x = jnp.asarray(x)
    return 1.0 / (1.0 - 0.5 * w * x * jnp.sum(c * h / (x[..., None] + mu), axis=-1))


def fit_once(folder: pathlib.Path, law: str) -> None:
    import jax

    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    import invsss
    import invsss.forward.light_terms as light_terms
    from fidelity import eroded, load_scene_pair, score

    if law == "exact":
        # reflectance_law reads chandrasekhar_h from its module at trace time.
        light_terms.chandrasekhar_h = exact_h
    pair = load_scene_pair(folder)
    with jax.enable_x64(True):
        fit = invsss.fit_pair(pair["source"], pair["target"], pair["depth"], pair["mask"], light_terms="shift,law",
                              light_buffers=pair["buffers"])
    terms = fit.light_terms
    err = terms["stderr"]["law_strength"]
    print(f"| {folder.name} | {law} | {score(fit.fitted[0], pair, eroded(pair['mask'], 2))['psnr']:.2f} | "
          f"{'/'.join(f'{w:.3f}' for w in terms['law'])} | {terms['law_strength']:.2f} | "
          f"{'?' if err is None else f'{err:.2f}'} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="+", type=pathlib.Path)
    parser.add_argument("--law", choices=("hapke", "exact"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.law:
        for folder in args.pairs:
            fit_once(folder, args.law)
        return
    print("| pair | H | PSNR (dB) | albedo | strength | stderr |\n|---|---|---|---|---|---|", flush=True)
    environment = {**os.environ, "INVSSS_NO_CACHE": "1"}
    for law in ("hapke", "exact"):
        subprocess.run([sys.executable, __file__, "--law", law, *map(str, args.pairs)], check=True, env=environment)


if __name__ == "__main__":
    main()
