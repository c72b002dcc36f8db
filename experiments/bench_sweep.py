"""Per-trial overhead of each sweep executor: what a trial costs beyond its own work.

Runs the same render sweep (one synthetic pair, ``sss_level`` x ``correction``
points from a Sobol' sample) twice per executor, with a small and a large number
of trials, each time into a fresh folder. The difference between the two runs
cancels what an executor pays once (starting processes or a cluster, importing
JAX, compiling), leaving the marginal cost of one more trial:

* ``wall/trial``: extra wall time per extra trial;
* ``compute/trial``: the render itself (the trials' ``compute_seconds``);
* ``overhead/trial``: ``wall/trial x workers - compute/trial``, the worker time a
  trial costs that is not its render: reading the pair, scoring, committing its
  files, the database row, and the executor's dispatch;
* ``fixed``: the once-per-sweep cost, ``wall(small) - wall/trial x small``.

Run from the repository root (renders are cheap, so overheads are visible; a
fit costs seconds to minutes, which these overheads are then compared with)::

    python experiments/bench_sweep.py [--small 8] [--large 40] [--executors local,local2,dask,dask-threads]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time

import invsss.sweeps as ex

HERE = os.path.dirname(os.path.abspath(__file__))
PAIR = os.path.join(HERE, "..", "data_synthetic", "fran_front")

EXECUTORS = {
    "local": ("in this process", lambda: ex.LocalExecutor(jobs=1), 1),
    "local2": ("2 spawned processes", lambda: ex.LocalExecutor(jobs=2), 2),
    "dask": ("Dask LocalCluster, 2 worker processes", lambda: ex.DaskExecutor(jobs=2), 2),
    "dask-threads": ("Dask LocalCluster, 2 worker threads", lambda: ex.DaskExecutor(jobs=2, processes=False), 2),
}


def _experiment(folder: str, trials: int) -> str:
    path = os.path.join(folder, f"bench_{trials}.toml")
    with open(path, "w") as f:
        f.write(
            'task = "render"\n'
            f'[data]\npairs = ["{os.path.abspath(PAIR)}/"]\n'
            '[base]\nprofile = "thesis-nir"\nmaxdd = 0.5\n'
            f'[sample]\nmethod = "sobol"\nn = {trials}\nseed = 0\n'
            "ranges.sss_level = [300.0, 1000.0]\nranges.correction = [0.0, 2500.0]\n"
        )
    return path


def _timed_run(folder: str, trials: int, make) -> tuple[float, float]:
    """(wall seconds, summed compute seconds) of one fresh sweep of ``trials`` renders."""
    out = os.path.join(folder, f"out_{trials}")
    shutil.rmtree(out, ignore_errors=True)
    experiment = ex.load(_experiment(folder, trials))
    start = time.perf_counter()
    summary = ex.run(experiment, out, executor=make(), log=None)
    wall = time.perf_counter() - start
    if summary.done != trials:
        sys.exit(f"bench_sweep: {summary.failed} trial(s) failed; see invsss sweep-report {out}")
    compute = sum(row["compute_seconds"] for row in ex.results(out, frame=False))
    return wall, compute


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--small", type=int, default=8)
    parser.add_argument("--large", type=int, default=40)
    parser.add_argument("--executors", default=",".join(EXECUTORS))
    args = parser.parse_args()
    print(f"render trials on {os.path.basename(PAIR)} (224x224); {os.cpu_count()} CPU cores")
    print(f"{'executor':<40} {'wall/trial':>11} {'compute/trial':>14} {'overhead/trial':>15} {'fixed':>8}")
    with tempfile.TemporaryDirectory() as folder:
        # Compile the render in this process first: executors that run trials
        # here would otherwise pay it in the first measured run only.
        _timed_run(folder, 1, lambda: ex.LocalExecutor(jobs=1))
        for key in args.executors.split(","):
            label, make, workers = EXECUTORS[key]
            wall_small, compute_small = _timed_run(folder, args.small, make)
            wall_large, compute_large = _timed_run(folder, args.large, make)
            extra = args.large - args.small
            per_wall = (wall_large - wall_small) / extra
            per_compute = (compute_large - compute_small) / extra
            overhead = per_wall * workers - per_compute
            fixed = wall_small - per_wall * args.small
            print(f"{label:<40} {per_wall * 1e3:>9.0f}ms {per_compute * 1e3:>12.0f}ms "
                  f"{overhead * 1e3:>13.0f}ms {fixed:>7.1f}s", flush=True)


if __name__ == "__main__":
    main()
