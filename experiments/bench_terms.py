"""What a fit with light terms costs beside the plain fit, cold and warm, on pair folders (issue 49).

For every pair folder and every setting (the plain fit, then each term set) one
fresh process, with an empty compilation cache and XLA's deterministic
scheduler (as the command line sets it), fits the pair twice with the command
line's defaults: its first fit is the cold one (compilation included), its
second the warm one (what a sweep worker pays after its first trial). It prints
per pair the seconds of both, their ratios to the plain fit's, the solver steps
and the fit's PSNR on its mask.

    python experiments/bench_terms.py PAIR_DIR [PAIR_DIR ...] [--terms shift,law] [--term-starts scan] [--json OUT]

``--terms`` takes term sets separated by ``;`` (``"shift,law;transmission"``); a
set with ``transmission`` also reads ``thickness.exr`` and ``key_irradiance.exr``.
``--term-starts`` sets the fit's ``term_starts`` (``auto``, the default, ``plain``
or ``scan``; docs/model.md, section 8, "Where a term fit starts").
``--json`` writes the rows as well (one per pair and setting), to compare runs of
two versions of the code: ``--compare A.json B.json`` prints B's PSNR less A's
and B's times over A's per pair and setting.

``--perturb SEED`` multiplies every target pixel by ``1 + 1e-12 n`` (``n`` standard
normal, drawn with ``SEED``) before the fits: about 4500 times float64's machine
epsilon, and far below anything a camera or a renderer could tell apart;
an edit of the code changes the numbers of a fit by rounding that grows over its
steps. Comparing such runs with an unperturbed one shows how far a pair's fit
moves for reasons no edit chose (docs/model.md,
section 8, "How far rounding alone moves a fit"), the floor under which a PSNR
or time difference between two versions of the code means nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

_T_START = time.perf_counter()

BUFFERS = ("normal", "light", "key", "fill_light")
TRANSMISSION_BUFFERS = ("thickness", "key_irradiance")


#: The relative size of ``--perturb``'s change of the targets.
PERTURBATION = 1e-12


def child(pair_dir: str, terms: str, cache_dir: str, term_starts: str, perturb: str = "0") -> None:
    """One process: two fits of ``pair_dir`` with ``terms`` ('' for plain); JSON on stdout."""
    from invsss.runtime.compile_cache import enable_compile_cache
    from invsss.runtime.determinism import use_deterministic_scheduler

    use_deterministic_scheduler()
    enable_compile_cache(cache_dir)
    from invsss import LightBuffers, load_pair, read_image
    from invsss.estimator import fit_pair

    pair = load_pair(*(os.path.join(pair_dir, f) for f in ("source.exr", "target.exr", "depth.exr", "mask.png")))
    target = pair.target
    if int(perturb):
        noise = np.random.default_rng(int(perturb)).standard_normal(np.shape(target))
        target = np.asarray(target, np.float64) * (1.0 + PERTURBATION * noise)
    options = {}
    if terms:
        names = BUFFERS + (TRANSMISSION_BUFFERS if "transmission" in terms else ())
        grey = pair.source.shape[-1] == 1
        found = {n: read_image(os.path.join(pair_dir, f"{n}.exr"), linear=True,
                               grey=grey and n in ("key", "thickness", "key_irradiance"))
                 for n in names if os.path.exists(os.path.join(pair_dir, f"{n}.exr"))}
        options = {"light_terms": terms, "light_buffers": LightBuffers(**found), "term_starts": term_starts}
    runs = []
    for _ in range(2):
        t0 = time.perf_counter()
        result = fit_pair(pair.source, target, pair.depth, pair.mask, **options)
        runs.append({"seconds": time.perf_counter() - t0, "iterations": int(result.iterations),
                     "psnr": float(result.psnr), "loss": float(result.loss)})
    print(json.dumps({"pair": os.path.basename(pair_dir.rstrip("/")), "terms": terms, "runs": runs}))


def measure(pair_dir: str, terms: str, term_starts: str, perturb: int = 0) -> dict:
    with tempfile.TemporaryDirectory(prefix="invsss-bench-terms-") as cache:
        done = subprocess.run([sys.executable, __file__, "--child", pair_dir, terms, cache, term_starts, str(perturb)],
                              capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"bench_terms: the fit of {pair_dir} with {terms or 'no terms'!r} failed:\n"
                         + done.stderr[-3000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def table(pair_dirs, term_sets, term_starts="auto", out=None, perturb=0) -> None:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"bench_terms: fit_pair with the CLI defaults, one fresh process per pair and setting (empty "
          f"compilation cache); term_starts={term_starts}; {os.cpu_count()} CPUs, load average {load:.1f}; seconds"
          + (f"; targets perturbed by {PERTURBATION:g} (seed {perturb})" if perturb else ""))
    header = f"{'pair':32s} {'setting':16s} {'cold':>7s} {'warm':>7s} {'x cold':>7s} {'x warm':>7s} " \
             f"{'steps':>6s} {'PSNR':>7s}"
    print(header)
    print("-" * len(header))
    rows = []
    for pair_dir in pair_dirs:
        plain = measure(pair_dir, "", term_starts, perturb)
        rows.append(plain)
        base = plain["runs"]
        for row in [plain] + [measure(pair_dir, terms, term_starts, perturb) for terms in term_sets]:
            if row is not plain:
                rows.append(row)
            cold, warm = row["runs"]
            print(f"{row['pair']:32s} {row['terms'] or 'plain':16s} {cold['seconds']:7.2f} {warm['seconds']:7.2f} "
                  f"{cold['seconds'] / base[0]['seconds']:7.2f} {warm['seconds'] / base[1]['seconds']:7.2f} "
                  f"{warm['iterations']:6d} {warm['psnr']:7.3f}", flush=True)
    if out:
        with open(out, "w") as f:
            json.dump(rows, f, indent=1)


def compare(first: str, second: str) -> None:
    """``second``'s PSNR less ``first``'s and its warm and cold times over ``first``'s."""
    with open(first) as f:
        a = {(r["pair"], r["terms"]): r for r in json.load(f)}
    with open(second) as f:
        b = {(r["pair"], r["terms"]): r for r in json.load(f)}
    print(f"{'pair':32s} {'setting':16s} {'dPSNR':>7s} {'cold':>6s} {'warm':>6s}")
    for key in a:
        if key in b:
            ra, rb = a[key]["runs"], b[key]["runs"]
            print(f"{key[0]:32s} {key[1] or 'plain':16s} {rb[1]['psnr'] - ra[1]['psnr']:+7.3f} "
                  f"{rb[0]['seconds'] / ra[0]['seconds']:6.2f} {rb[1]['seconds'] / ra[1]['seconds']:6.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pairs", nargs="*", help="pair folders")
    parser.add_argument("--terms", default="shift,law", help="term sets separated by ';' (default shift,law)")
    parser.add_argument("--term-starts", default="auto", choices=("auto", "plain", "scan"),
                        help="the fit's term_starts (default auto)")
    parser.add_argument("--json", default=None, metavar="OUT", help="also write the rows as JSON")
    parser.add_argument("--compare", nargs=2, default=None, metavar=("A", "B"), help="compare two --json files")
    parser.add_argument("--perturb", type=int, default=0, metavar="SEED",
                        help=f"multiply the targets by 1 + {PERTURBATION:g} n, n drawn with SEED (default 0: not)")
    parser.add_argument("--child", nargs=5, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(*args.child)
    elif args.compare:
        compare(*args.compare)
    else:
        if not args.pairs:
            parser.error("give pair folders (or --compare A B)")
        table(args.pairs, [t for t in args.terms.split(";") if t], args.term_starts, args.json, args.perturb)


if __name__ == "__main__":
    main()
