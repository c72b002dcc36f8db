"""Sum-of-Gaussians fits of every published profile, with their residuals.

Fits Jensen's skin1 dipole (RGB, shared variances), Christensen-Burley (d = 1 mm),
the thesis's Table 5.1 and d'Eon & Luebke's table with ``invsss.fit_sum_of_gaussians``
and prints one row per fit:

    python experiments/fit_profiles.py [--out DIR]

``rms`` is the r-weighted residual relative to the r-weighted profile (what the fit
minimises), ``max rel`` the largest pointwise relative error on a dense grid where
the profile is at least 1 % of its peak (for Burley from r = d / 4 on), ``total`` the fit's total diffuse
reflectance (sum of weights) over the profile's (closed form). With ``--out`` each fit
is written as a JSON profile file (``invsss.load_profile`` reads them). The
``jensen-skin1`` row is the table ``invsss.forward.profiles.JENSEN_SKIN1_SOG``.
"""

from __future__ import annotations

import argparse
import functools
import json
import pathlib
import time

import jax
import jax.numpy as jnp
import numpy as np

import invsss


def _cases():
    s = jnp.asarray(invsss.JENSEN_SKIN1["sigma_s_prime"])
    a = jnp.asarray(invsss.JENSEN_SKIN1["sigma_a"])
    dipole = functools.partial(invsss.jensen_dipole, sigma_s_prime=s, sigma_a=a)
    burley = functools.partial(invsss.burley, d=1.0, A=1.0)
    thesis = invsss.load_profile("thesis-nir")
    deon = invsss.load_profile("deon-skin")
    return [
        # name, profile, closed-form total, fitted r range (mm), K, smallest r for max rel
        ("jensen-skin1", dipole, invsss.jensen_dipole_total(s, a), 8.0, 4, 0.0),
        ("jensen-skin1", dipole, invsss.jensen_dipole_total(s, a), 8.0, 5, 0.0),
        ("jensen-skin1", dipole, invsss.jensen_dipole_total(s, a), 8.0, 6, 0.0),
        # Burley's 1/r peak is out of any Gaussian's reach: judge from r = d / 4.
        ("burley d=1", burley, jnp.asarray(1.0), 12.0, 4, 0.25),
        ("burley d=1", burley, jnp.asarray(1.0), 12.0, 5, 0.25),
        ("burley d=1", burley, jnp.asarray(1.0), 16.0, 6, 0.25),
        ("thesis-nir", thesis, thesis.total_reflectance(), 12.0, 3, 0.0),
        ("thesis-nir", thesis, thesis.total_reflectance(), 12.0, 4, 0.0),
        ("deon-skin", deon, deon.total_reflectance(), 12.0, 6, 0.0),
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=pathlib.Path, help="write each fit as a JSON profile here")
    parser.add_argument("--samples", type=int, default=121)
    args = parser.parse_args(argv)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)

    header = (
        f"{'profile':<14}{'K':>3}{'r range':>10}{'rms':>10}{'max rel':>10}  "
        f"{'total fit / closed':<24}{'steps':>6}{'s':>6}"
    )
    print(header)
    print("-" * len(header))
    with jax.enable_x64(True):
        for name, profile, total, r_max, k, r_judge in _cases():
            r = jnp.linspace(0.0, r_max, args.samples)
            start = time.perf_counter()
            fit = invsss.fit_sum_of_gaussians(r, profile(r), num_gaussians=k, source=f"SoG fit of {name}")
            seconds = time.perf_counter() - start
            dense = jnp.linspace(r_judge, r_max, 2000)
            truth = np.asarray(profile(dense))
            visible = truth >= 0.01 * truth.max(axis=0)
            max_rel = np.max(np.abs(np.asarray(fit.profile(dense)) / truth - 1.0)[visible])
            ratio = np.atleast_1d(np.asarray(fit.profile.total_reflectance() / total))
            ratio_text = " ".join(f"{x:.3f}" for x in ratio)
            print(
                f"{name:<14}{k:>3}{f'0-{r_max:g} mm':>10}{float(fit.rms):>10.2e}{max_rel:>10.2e}  "
                f"{ratio_text:<24}{int(fit.num_steps):>6}{seconds:>6.1f}"
            )
            if args.out:
                path = args.out / f"{name.replace(' ', '_').replace('=', '')}_K{k}.json"
                path.write_text(json.dumps(fit.to_dict(), indent=2))
            if name == "jensen-skin1" and k == 5:
                np.set_printoptions(precision=6, suppress=False)
                print("    variances", np.asarray(fit.profile.variances).round(6).tolist())
                print("    weights  ", np.asarray(fit.profile.weights).round(6).tolist())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
