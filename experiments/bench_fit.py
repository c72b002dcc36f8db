"""Fit time and accuracy: invsss's jitted Levenberg-Marquardt against SciPy's TRF.

One synthetic pair (a textured, shaded bulge with ripples, so depth slopes lie on
both sides of ``maxdd``) is rendered with the ``sog`` model at known parameters,
with gain, offset and 0.5 % noise. On that pair the script times:

``invsss.fit_pair``
    the whole estimator, one start, no robust reweighting: scan of start points,
    LM solve, active set, standard errors, PSNR/SSIM, misalignment check;
``invsss LM``
    only the solve: optimistix Levenberg-Marquardt stepped by
    :func:`invsss.estimator.solve.run_solver` (jitted step, forward-mode Jacobian);
``scipy trf 2-point``
    ``scipy.optimize.least_squares(method="trf", jac="2-point")`` on the SAME
    residual: the estimator's own :class:`~invsss.estimator.objective.Objective`
    (same parametrisation, same variable projection of gains, offsets and weights),
    called through a jitted function and NumPy, from the SAME starting point;
``scipy trf jax-jac``
    the same SciPy solver given the exact Jacobian (``jax.jacfwd``, jitted), to
    separate the cost of finite differences from the cost of the algorithm.

The problem is the estimator's own: :func:`invsss.estimator.build_problem` makes
the objective pytree and the starting point (the best point of its start grid)
that ``fit_pair`` hands its solver first, and every method is timed on that
objective from that point.
Times are medians over ``--repeats`` runs; compile times (first call minus the
median) are a separate column. Errors are absolute differences from the truth;
``weights`` is the largest over the Gaussians (weights normalised to sum 1). The
last lines print how many LM steps reach the final loss (the rest are the
termination tail) and the time ratios.

The profile has three Gaussians, the distinct variances of the thesis profile
(Table 5.1): its two Gaussians of nearly equal variance (0.549 and 0.557 mm^2)
would make their weight split undetermined and measure that degeneracy instead of
the solvers.

``--stopping PAIR_DIR [PAIR_DIR ...]`` fits each pair folder with the command
line's defaults twice, without and with the stall test of
:mod:`invsss.estimator.solve` (the fit option ``stall_test``), and prints
the steps, the time, ``sss_level`` and ``correction`` with their standard
errors, and how much chi^2 the stall test left untaken. ``--jacobian PAIR_DIR
[PAIR_DIR ...]`` does the same for the solvers' Jacobian, forward mode against
forward differences (the fit option ``solver_jacobian``;
:class:`invsss.estimator.solve.DenseJacobian`).

``--canvas PAIR_DIR`` fits three crops of a pair (its full size and two smaller
ones that keep the mask off their last row and column) one after another in a
fresh process, as a sweep worker over photographs of slightly different sizes
would: once at their own sizes, once on one canvas (``FitOptions(canvas=...)``,
the full size). It prints each fit's seconds, the solver step's compilations
and the estimates of both runs, which must agree.

``--breakdown PAIR_DIR`` instead profiles ``fit_pair`` with the command line's
defaults on a pair folder (``source.exr``, ``target.exr``, ``depth.exr``,
``mask.png``, e.g. ``data_synthetic/fran_front``), stage by stage: import,
reading, building the problem (its start scan apart), every solve (starts, robust
rounds, active-set rounds), the covariance, the rest of the report, and the
trace/lowering/XLA compile time of each jitted function with its compile count.
The solver's step compiles on a second thread while the start scan's loss
compiles, so these times overlap: the row "of it, wall time" counts the seconds
during which anything was compiling once.
It runs three fits measured in one run: a fresh process with an empty persistent
compilation cache (cold), a second fit in that process (what a sweep worker does
after its first trial), a fresh process on the cache the first one wrote
(warm cache: the first process to use an entry tries it in a child process
first, :mod:`invsss.runtime.executable_entries`), and one more fresh process
on that cache (verified: what every later run of the command line meets);
each child process prints JSON, the parent the table. ``synthetic:N`` in place
of a folder fits this script's model-made N x N pair (rendered in the child,
not timed as reading). The table names JAX's device and whether the solver
loop steps ahead (:func:`invsss.estimator.solve.step_ahead`). Per solver step
it gives the loop's wall time and splits it into the host dispatching the
jitted step, the wait for the device's result (the step's one device-to-host
read: its loss and stopping flags) and the host's own work between steps, so a
device left idle by the host shows; a loop that steps ahead is not made to
wait for each step, so its wait counts under "between", and its "solver
steps" count the steps it dispatched and then dropped. "same history" says
whether the fits took the same steps to the same losses, bit for bit.

Usage::

    python experiments/bench_fit.py [--size 128] [--repeats 3] [--max-steps 200]
    python experiments/bench_fit.py --breakdown data_synthetic/fran_front
    python experiments/bench_fit.py --breakdown synthetic:1024 [--cold-only]
    python experiments/bench_fit.py --stopping data_synthetic/pt_face_940 data_synthetic/fran_front
    python experiments/bench_fit.py --jacobian data_synthetic/fran_front data_synthetic/pt_face_940
    python experiments/bench_fit.py --canvas data_synthetic/fran_front
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict

_T_START = time.perf_counter()  # before the imports below: the import stage

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.optimize import least_squares

import invsss
from invsss.estimator import FitOptions, build_problem, fit_pair
from invsss.estimator.solve import make_solver, run_solver

PROFILE = {"weights": [0.3, 0.45, 0.25], "variances": [0.549, 2.099, 8.749]}
TRUTH = {"sss_level": 900.0, "correction": 300.0, "maxdd": 0.8,
         "weights": [0.25, 0.45, 0.30], "variances": PROFILE["variances"]}
GAIN, OFFSET, NOISE = 0.8, 0.02, 0.005


def make_scene(size: int, seed: int = 0):
    """(source, target, depth, mask): depth in mm, target = gain * render + offset + noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    c = (size - 1) / 2
    r2 = ((x - c) / (0.47 * size)) ** 2 + ((y - c) / (0.49 * size)) ** 2
    # Ripples scaled with the image, so the slope distribution does not depend on --size.
    period = size / 16.0
    # The bulge's relief (mm) grows with the image up to 128 px and no further,
    # so that depth stays near 600 mm (and > 0) at any size (synthetic:1024).
    relief = 0.9 * min(size, 128)
    depth = 600.0 - relief * np.sqrt(np.clip(1.0 - r2, 0.0, None)) + 4.0 * np.sin(x / period)
    mask = (r2 < 0.8).astype(np.float64)
    fine = gaussian_filter(rng.standard_normal((size, size)), 0.7)
    coarse = gaussian_filter(rng.standard_normal((size, size)), 3.0)
    albedo = np.clip(0.55 + 0.2 * fine / fine.std() + 0.1 * coarse / coarse.std(), 0.05, None)
    gy, gx = np.gradient(depth)
    shading = np.clip((-0.4 * gx - 0.5 * gy + 0.77) / np.sqrt(gx**2 + gy**2 + 1.0), 0.05, None)
    source = albedo * shading
    with jax.enable_x64(True):
        clean = np.asarray(invsss.render(source, depth, mask, invsss.SSSParams(**TRUTH)))
    clean = GAIN * clean + OFFSET
    target = clean + NOISE * float(np.mean(clean[mask > 0])) * rng.standard_normal(clean.shape)
    return source, target, depth, mask


def fit_options(max_steps: int) -> FitOptions:
    """One start, no robust reweighting: the estimator's plain problem."""
    return FitOptions(profile=PROFILE, n_starts=1, robust=None, max_steps=max_steps)


def capture_problem(scene, max_steps: int):
    """The objective and start of ``fit_pair``'s first solve, and the fit's result.

    Built by :func:`~invsss.estimator.build_problem`, so it is exactly the
    estimator's problem. Returns ``(objective, z0, result)``; call under x64.
    """
    source, target, depth, mask = scene
    problem = build_problem([(source, target, depth, mask)], fit_options(max_steps))
    return problem.objective, np.asarray(problem.z0), run_fit(scene, max_steps)


def run_fit(scene, max_steps: int):
    source, target, depth, mask = scene
    return fit_pair(source, target, depth, mask, options=fit_options(max_steps))


@eqx.filter_jit
def _residual(objective, z):
    return objective(z)[0]


@eqx.filter_jit
def _jacobian(objective, z):
    return jax.jacfwd(lambda u: objective(u)[0])(z)


@eqx.filter_jit
def _estimate(objective, z):
    """Natural parameters, normalised weights and the loss at ``z``."""
    natural, _, _, coef, _ = objective.linear(z)
    weights = coef[:, 0] / jnp.sum(coef[:, 0])
    return natural["sss_level"], natural["correction"], natural["maxdd"], weights, objective.loss(z)


def errors(objective, z) -> dict:
    level, correction, maxdd, weights, loss = (np.asarray(a) for a in _estimate(objective, jnp.asarray(z)))
    truth_w = np.asarray(TRUTH["weights"]) / np.sum(TRUTH["weights"])
    return {
        "loss": float(loss),
        "sss_level": abs(float(level) - TRUTH["sss_level"]),
        "correction": abs(float(correction) - TRUTH["correction"]),
        "maxdd": abs(float(maxdd) - TRUTH["maxdd"]),
        "weights": float(np.max(np.abs(weights - truth_w))),
    }


def result_errors(result) -> dict:
    """:func:`errors` for a :class:`~invsss.estimator.FitResult`."""
    params = result.params
    weights = np.asarray(params.weights) / np.sum(params.weights)
    truth_w = np.asarray(TRUTH["weights"]) / np.sum(TRUTH["weights"])
    return {
        "loss": float(result.loss),
        "sss_level": abs(float(params.sss_level) - TRUTH["sss_level"]),
        "correction": abs(float(params.correction) - TRUTH["correction"]),
        "maxdd": abs(float(params.maxdd) - TRUTH["maxdd"]),
        "weights": float(np.max(np.abs(weights - truth_w))),
    }


def compile_time(call) -> float:
    """First call's time minus the median of three more: the JIT compile."""
    first, median, _ = timed(call, 3)
    return first - median


def timed(run, repeats: int):
    """(first-call seconds, median seconds of ``repeats`` further calls, last output)."""
    t0 = time.perf_counter()
    out = run()
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = run()
        times.append(time.perf_counter() - t0)
    return first, float(np.median(times)), out


def steps_to_final(history, tolerance=1e-6) -> int:
    """The first step whose loss is within ``tolerance`` (relative) of the last."""
    history = np.asarray(history)
    close = np.abs(history - history[-1]) <= tolerance * abs(history[-1])
    return int(np.argmax(close)) + 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=128, help="image side in pixels (default 128)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per method (default 3)")
    parser.add_argument("--max-steps", type=int, default=200, help="solver step limit (default 200)")
    parser.add_argument("--breakdown", metavar="PAIR_DIR", default=None,
                        help="profile fit_pair stage by stage on this pair folder, cold and warm")
    parser.add_argument("--breakdown-child", metavar="CACHE_DIR", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--cold-only", action="store_true",
                        help="--breakdown: only the cold process (its fit and a second fit in it)")
    parser.add_argument("--light-terms", metavar="TERMS", default="",
                        help="--breakdown: fit these light terms (e.g. shift,law) with the pair folder's "
                             "buffers; the plain fit inside the term fit is its own row")
    parser.add_argument("--canvas", metavar="PAIR_DIR", default=None,
                        help="three crops of a pair fitted at their own sizes and on one canvas")
    parser.add_argument("--canvas-child", metavar="ON", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--stopping", metavar="PAIR_DIR", nargs="+", default=None,
                        help="fit these pair folders with and without the stall test; steps, time, estimates")
    parser.add_argument("--jacobian", metavar="PAIR_DIR", nargs="+", default=None,
                        help="fit these pair folders with forward-mode and difference Jacobians")
    args = parser.parse_args()
    if args.stopping is not None:
        stopping(args.stopping)
        return
    if args.jacobian is not None:
        jacobian(args.jacobian)
        return
    if args.canvas_child is not None:
        canvas_child(args.canvas, args.canvas_child == "on")
        return
    if args.canvas is not None:
        canvas(args.canvas)
        return
    if args.breakdown_child is not None:
        breakdown_child(args.breakdown, args.breakdown_child, args.light_terms)
        return
    if args.breakdown is not None:
        breakdown(args.breakdown, cold_only=args.cold_only, light_terms=args.light_terms)
        return

    scene = make_scene(args.size)
    rows = {}
    with jax.enable_x64(True):
        # The whole estimator; its first call compiles everything it uses, the LM step included.
        t0 = time.perf_counter()
        objective, z0, _ = capture_problem(scene, args.max_steps)
        first = time.perf_counter() - t0
        _, median, result = timed(lambda: run_fit(scene, args.max_steps), args.repeats)
        rows["invsss.fit_pair"] = (median, f"{first - median:.2f}", result.iterations,
                                   f"{result.iterations} (f+J)", result_errors(result))

        # Only the LM solve, on the captured objective and start.
        lm = make_solver("lm")
        _, median, record = timed(lambda: run_solver(lm, objective, z0, args.max_steps), args.repeats)
        rows["invsss LM"] = (median, "in fit", record.steps, f"{record.steps} (f+J)",
                             errors(objective, record.z))

        # SciPy TRF with a finite-difference Jacobian, on the same jitted residual.
        calls = [0]

        def fun(z):
            calls[0] += 1
            return np.asarray(_residual(objective, jnp.asarray(z)))

        def jac(z):
            return np.asarray(_jacobian(objective, jnp.asarray(z)))

        compile_residual = compile_time(lambda: fun(z0))
        compile_jacobian = compile_time(lambda: jac(z0))

        def run_scipy(jacobian):
            calls[0] = 0
            return least_squares(fun, z0, jac=jacobian, method="trf")

        _, median, sol = timed(lambda: run_scipy("2-point"), args.repeats)
        rows["scipy trf 2-point"] = (median, f"{compile_residual:.2f}", sol.njev, f"{calls[0]} f",
                                     errors(objective, sol.x))
        # The same with the exact Jacobian: separates finite differences from the algorithm.
        _, median, sol_j = timed(lambda: run_scipy(jac), args.repeats)
        rows["scipy trf jax-jac"] = (median, f"{compile_jacobian:.2f}", sol_j.njev,
                                     f"{calls[0]} f + {sol_j.njev} J", errors(objective, sol_j.x))

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"bench_fit: {args.size}x{args.size} sog, K=3, {len(z0)} nonlinear unknowns "
          f"(sss_level, correction, maxdd; weights, gain, offset projected out), "
          f"{args.repeats} repeats, {os.cpu_count()} CPUs, load average {load:.1f}")
    print(f"truth: sss_level {TRUTH['sss_level']:g}, correction {TRUTH['correction']:g}, "
          f"maxdd {TRUTH['maxdd']:g}, weights {TRUTH['weights']}")
    header = (f"{'method':<19}{'time s':>9}{'compile s':>11}{'iters':>7}  {'evaluations':<15}"
              f"{'final loss':>12}{'|dL|':>9}{'|dc|':>9}{'|d delta|':>11}{'|dw| max':>10}")
    print(header)
    print("-" * len(header))
    for name, (seconds, compile_s, iters, evals, err) in rows.items():
        print(f"{name:<19}{seconds:>9.3f}{compile_s:>11}{iters:>7}  {evals:<15}"
              f"{err['loss']:>12.5e}{err['sss_level']:>9.3f}{err['correction']:>9.3f}"
              f"{err['maxdd']:>11.5f}{err['weights']:>10.5f}")
    print("time: median of the repeats; compile: first call minus that (fit_pair's includes the LM "
          "step; the scipy rows compile the jitted residual / Jacobian)")
    print(f"invsss LM is within 1e-6 of its final loss after step {steps_to_final(record.history)} "
          f"of {record.steps}")
    times = {name: row[0] for name, row in rows.items()}
    print(f"scipy trf 2-point time / invsss LM time       = "
          f"{times['scipy trf 2-point'] / times['invsss LM']:.2f}")
    print(f"scipy trf 2-point time / invsss.fit_pair time = "
          f"{times['scipy trf 2-point'] / times['invsss.fit_pair']:.2f}")


# ------------------------------------------------------------------ --breakdown

_COMPILE_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "xla",
    "/jax/compilation_cache/cache_retrieval_time_sec": "cache load",
}


class _Stages:
    """Wall seconds per stage (nested stages are also counted in their parent)."""

    def __init__(self):
        self.seconds: dict = defaultdict(float)
        self.counts: dict = defaultdict(int)

    def wrap(self, module, name, stage):
        """Replace ``module.name`` with a timed wrapper; ``stage`` is a string or
        a function of the call's arguments giving one."""
        inner = getattr(module, name)

        def timed_call(*args, **kwargs):
            label = stage(*args, **kwargs) if callable(stage) else stage
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                self.seconds[label] += time.perf_counter() - t0
                self.counts[label] += 1

        setattr(module, name, timed_call)


def _solve_label(solver, objective, z0, max_steps, on_step=None, *rest, **options):
    # fit.py's ``run`` labels each solve ("start 2", "robust 1", "active set 1").
    label = on_step.stages[-1][0] if on_step is not None and on_step.stages else "solve"
    return "solve: " + label.rstrip("0123456789").strip()


def breakdown_child(pair_dir: str, cache_dir: str, light_terms: str = "") -> None:
    """One process: import, read, fit twice; print the stages as JSON."""
    from jax import monitoring

    import invsss.estimator.core as core_module
    import invsss.estimator.fit as fit_module
    import invsss.estimator.problem as problem_module
    import invsss.estimator.search as search_module
    import invsss.estimator.summary as summary_module
    from invsss.runtime.compile_cache import enable_compile_cache
    import invsss.io  # noqa: F401  (loaded before the reading stage is timed)

    imported = time.perf_counter() - _T_START
    from invsss.cli.progress import covered_seconds as _covered_seconds  # the union of compile intervals, as the CLI counts it

    enable_compile_cache(cache_dir)
    compiles: dict = defaultdict(lambda: defaultdict(float))
    spans: list = []  # (start, end) of every compile event: the solver step compiles on a second thread

    def on_duration(event, duration, fun_name="?", **_):
        kind = _COMPILE_EVENTS.get(event)
        if kind is not None:
            end = time.perf_counter()
            spans.append((end - duration, end))
            # Tracing names a function "f", lowering and XLA "jit(f)": one row each.
            if fun_name.startswith("jit(") and fun_name.endswith(")"):
                fun_name = fun_name[4:-1]
            if kind == "cache load":
                fun_name = "(persistent cache reads)"
            compiles[fun_name][kind] += duration
            compiles[fun_name][kind + " n"] += 1

    monitoring.register_event_duration_secs_listener(on_duration)
    stages = _Stages()
    stages.wrap(core_module, "build_problem", "build problem (with start scan)")
    stages.wrap(problem_module, "choose_starts", "  start scan")
    stages.wrap(search_module, "run_solver", _solve_label)
    for module in (search_module, summary_module):
        stages.wrap(module, "evaluate",
                    lambda objective, z, flag: "evaluate + linearise" if bool(flag) else "evaluate")
    stages.wrap(summary_module, "gauss_newton_uncertainty", "covariance")
    stages.wrap(core_module, "summarise", "report (all)")
    if light_terms:
        # The term fit runs the plain model's fit first (estimator.stages.light_terms):
        # each innermost fit is a row of its own.
        stages.wrap(fit_module, "core", lambda call: "core: " + ("with the terms" if call.options.light_terms
                                                                 else "plain model"))
    import invsss.estimator.solve as solve_module

    steps = {"dispatch": 0.0, "wait": 0.0, "between": 0.0, "loop": 0.0, "n": 0, "last": None}
    iterate = solve_module._iterate
    ahead = solve_module.step_ahead()

    def timed_iterate(*args, **kwargs):
        # Replace the step function (argument 10) by one that times dispatch
        # and the wait for its result separately. A loop that steps ahead must
        # not be made to wait for each step here: then only the dispatch is
        # timed, and the wait falls into "between".
        args = list(args)
        inner = args[10]

        def step(*a, **k):
            t0 = time.perf_counter()
            if steps["last"] is not None:
                steps["between"] += t0 - steps["last"]
            out = inner(*a, **k)
            t1 = time.perf_counter()
            if not ahead:
                jax.block_until_ready(out[2:])  # loss, dof, done, ok: what the loop reads
            steps["last"] = time.perf_counter()
            steps["dispatch"] += t1 - t0
            steps["wait"] += steps["last"] - t1
            steps["n"] += 1
            return out

        args[10] = step
        t0 = time.perf_counter()
        try:
            return iterate(*args, **kwargs)
        finally:
            steps["loop"] += time.perf_counter() - t0
            steps["last"] = None

    solve_module._iterate = timed_iterate

    t0 = time.perf_counter()
    pair = _pair_source(pair_dir)
    terms = {}
    if light_terms:
        from invsss import LightBuffers, read_image

        found = {name: os.path.join(pair_dir, f"{name}.exr") for name in ("normal", "light", "key", "fill_light")}
        buffers = {name: read_image(path, linear=True, grey=name == "key" and pair.source.shape[-1] == 1)
                   for name, path in found.items() if os.path.exists(path)}
        terms = {"light_terms": light_terms, "light_buffers": LightBuffers(**buffers)}
    reading = time.perf_counter() - t0
    runs = []
    for _ in range(2):
        stages.seconds.clear()
        stages.counts.clear()
        compiles.clear()
        spans.clear()
        steps.update(dispatch=0.0, wait=0.0, between=0.0, loop=0.0, n=0, last=None)
        t0 = time.perf_counter()
        result = fit_module.fit_pair(pair.source, pair.target, pair.depth, pair.mask, **terms)
        total = time.perf_counter() - t0
        runs.append({
            "fit": total, "stages": dict(stages.seconds), "counts": dict(stages.counts),
            "compiles": {k: dict(v) for k, v in compiles.items()},
            "compiling": _covered_seconds(spans),
            "iterations": result.iterations, "loss": float(result.loss),
            "converged": bool(result.converged),
            "steps": {k: v for k, v in steps.items() if k != "last"},
            "history": [float(x).hex() for x in np.ravel(result.history)],
        })
    device = jax.devices()[0]
    print(json.dumps({"import": imported, "reading": reading, "runs": runs, "ahead": ahead,
                      "device": f"{device.platform}: {device.device_kind}"}))


def _pair_source(pair_dir: str):
    """A pair folder's pair, or ``synthetic:N``: this script's model-made N x N pair."""
    if pair_dir.startswith("synthetic:"):
        from types import SimpleNamespace

        source, target, depth, mask = make_scene(int(pair_dir.split(":", 1)[1]))
        return SimpleNamespace(source=source.astype(np.float32), target=target.astype(np.float32),
                               depth=depth.astype(np.float32), mask=mask.astype(np.float32))
    return read_pair_folder(pair_dir)


def _child_run(pair_dir: str, cache_dir: str, light_terms: str = "") -> dict:
    command = [sys.executable, __file__, "--breakdown", pair_dir, "--breakdown-child", cache_dir,
               "--light-terms", light_terms]
    env = {k: v for k, v in os.environ.items() if k != "INVSSS_NO_CACHE"}
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise SystemExit(f"bench_fit: the child process failed (exit status {done.returncode}):\n"
                         + done.stderr[-4000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def breakdown(pair_dir: str, cold_only: bool = False, light_terms: str = "") -> None:
    """Cold process, second fit in it, warm-cache process, verified-cache process: one table."""
    with tempfile.TemporaryDirectory(prefix="invsss-bench-cache-") as cache:
        cold = _child_run(pair_dir, cache, light_terms)
        columns = {"cold": (cold, cold["runs"][0]), "2nd fit": (cold, cold["runs"][1])}
        if not cold_only:
            warm = _child_run(pair_dir, cache, light_terms)
            verified = _child_run(pair_dir, cache, light_terms)
            columns.update({"warm cache": (warm, warm["runs"][0]), "verified": (verified, verified["runs"][0])})
    stage_names = []
    for _, run in columns.values():
        stage_names += [k for k in run["stages"] if k not in stage_names]
    functions = []
    for _, run in columns.values():
        functions += [k for k in run["compiles"] if k not in functions]

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    with_terms = f" and --light-terms {light_terms}" if light_terms else ""
    print(f"bench_fit --breakdown {pair_dir}: fit_pair with the CLI defaults{with_terms}; {os.cpu_count()} CPUs, "
          f"load average {load:.1f}; JAX device {cold.get('device')}; "
          f"steps ahead: {'yes' if cold.get('ahead') else 'no'}; seconds (calls)")
    header = f"{'stage':<34}" + "".join(f"{name:>16}" for name in columns)
    print(header)
    print("-" * len(header))

    def row(label, values):
        print(f"{label:<34}" + "".join(f"{v:>16}" for v in values))

    row("import", [f"{proc['import']:.2f}" if name != "2nd fit" else "-"
                   for name, (proc, _) in columns.items()])
    row("reading", [f"{proc['reading']:.2f}" if name != "2nd fit" else "-"
                    for name, (proc, _) in columns.items()])
    row("fit_pair (all)", [f"{run['fit']:.2f}" for _, run in columns.values()])
    for stage in stage_names:
        row(stage, [f"{run['stages'].get(stage, 0.0):.2f} ({run['counts'].get(stage, 0)})"
                    for _, run in columns.values()])
    row("iterations", [str(run["iterations"]) for _, run in columns.values()])
    row("solver steps", [str(run["steps"]["n"]) for _, run in columns.values()])
    for part, label in (("loop", "  solver loop, ms/step"), ("dispatch", "  host dispatch, ms/step"),
                        ("wait", "  wait for device, ms/step"), ("between", "  host between steps, ms/step")):
        row(label, [f"{1e3 * run['steps'][part] / max(run['steps']['n'], 1):.2f}" for _, run in columns.values()])
    histories = [run.get("history") for _, run in columns.values()]
    row("same history (bitwise)", ["-" if h is None else ("yes" if h == histories[0] else "no") for h in histories])
    row("loss", [f"{run['loss']:.4e}" for _, run in columns.values()])
    print("compilation per jitted function: trace+lower+XLA seconds (compilations); "
          "cache loads seconds (loads)")
    for fun in sorted(functions, key=lambda f: -sum(
            v for k, v in cold["runs"][0]["compiles"].get(f, {}).items() if not k.endswith(" n"))):
        cells = []
        for _, run in columns.values():
            c = run["compiles"].get(fun, {})
            built = c.get("trace", 0.0) + c.get("lower", 0.0) + c.get("xla", 0.0)
            cells.append(f"{built:.2f} ({int(c.get('xla n', 0))})"
                         + (f" L{int(c['cache load n'])}" if c.get("cache load n") else ""))
        row("  " + fun[:32], cells)
    totals = []
    for _, run in columns.values():
        totals.append(sum(v for c in run["compiles"].values() for k, v in c.items()
                          if k in ("trace", "lower", "xla")))
    row("compile total (trace+lower+XLA)", [f"{t:.2f}" for t in totals])
    walls = [run.get("compiling", 0.0) for _, run in columns.values()]
    row("  of it, wall time", [f"{t:.2f}" for t in walls])
    c, s2 = columns["cold"][1]["fit"], columns["2nd fit"][1]["fit"]
    ratios = [f"2nd fit in process / cold = {s2 / c:.2f}"]
    if not cold_only:
        w, v = columns["warm cache"][1]["fit"], columns["verified"][1]["fit"]
        ratios = [f"warm cache / cold = {w / c:.2f}", f"verified / cold = {v / c:.2f}"] + ratios
    print("ratios: " + "; ".join(ratios + [f"compiling's share of the cold fit's wall time = {walls[0] / c:.2f}"]))


# ------------------------------------------------------------------ --canvas


def _crops(mask) -> list[tuple[int, int]]:
    """The full size and two smaller ones whose last row and column the mask stays off."""
    h, w = mask.shape
    rows, cols = np.nonzero(np.asarray(mask) > 0)
    low_h, low_w = int(rows.max()) + 2, int(cols.max()) + 2  # one clear row and column at least
    return [(h, w), (max(low_h, h - 6), max(low_w, w - 10)), (max(low_h, h - 10), max(low_w, w - 4))]


def canvas_child(pair_dir: str, on: bool) -> None:
    """One fresh process: fit the crops in turn; print JSON (seconds, step compilations, estimates)."""
    from jax import monitoring

    steps = []

    def on_duration(event, duration, fun_name="", **_):
        if event == "/jax/core/compile/backend_compile_duration" and fun_name == "jit(_step)":
            steps[-1] += 1

    monitoring.register_event_duration_secs_listener(on_duration)
    pair = read_pair_folder(pair_dir)
    crops = _crops(pair.mask)
    runs = []
    for h, w in crops:
        steps.append(0)
        t0 = time.perf_counter()
        result = fit_pair(*(np.asarray(x)[:h, :w] for x in (pair.source, pair.target, pair.depth, pair.mask)),
                          canvas=crops[0] if on else None)
        runs.append({"size": [h, w], "seconds": time.perf_counter() - t0, "step compilations": steps[-1],
                     "values": {k: float(result.values[k]) for k in ("sss_level", "correction", "maxdd")},
                     "warnings": [m for m in result.warnings if m.startswith("canvas")]})
    print(json.dumps(runs))


def canvas(pair_dir: str) -> None:
    """Crops of one pair at their own sizes, then on one canvas, each in a fresh process."""
    env = {**os.environ, "INVSSS_NO_CACHE": "1"}  # compilations in the process, not loads from disk
    out = {}
    for setting in ("off", "on"):
        command = [sys.executable, __file__, "--canvas", pair_dir, "--canvas-child", setting]
        done = subprocess.run(command, capture_output=True, text=True, env=env, check=True)
        out[setting] = json.loads(done.stdout.strip().splitlines()[-1])
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"bench_fit --canvas {pair_dir}: fit_pair with the CLI defaults on three crops, one fresh process "
          f"per setting; {os.cpu_count()} CPUs, load average {load:.1f}")
    header = (f"{'crop':>10s} {'own size s':>11s} {'steps comp.':>11s} {'canvas s':>9s} {'steps comp.':>11s} "
              f"{'sss_level own':>14s} {'on canvas':>10s}")
    print(header)
    print("-" * len(header))
    for a, b in zip(out["off"], out["on"]):
        print(f"{a['size'][0]:>4d} x {a['size'][1]:<3d} {a['seconds']:11.2f} {a['step compilations']:11d} "
              f"{b['seconds']:9.2f} {b['step compilations']:11d} {a['values']['sss_level']:14.4f} "
              f"{b['values']['sss_level']:10.4f}")
        for message in b["warnings"]:
            print("   " + message)
    total = [sum(r["seconds"] for r in out[k]) for k in ("off", "on")]
    moved = max(abs(b["values"][k] / a["values"][k] - 1.0) for a, b in zip(out["off"], out["on"])
                for k in ("sss_level", "correction", "maxdd"))
    print(f"all three: {total[0]:.1f} s at their own sizes, {total[1]:.1f} s on one canvas "
          f"(ratio {total[1] / total[0]:.2f}); largest relative difference of an estimate {moved:.1e}")


def read_pair_folder(pair_dir: str):
    """The pair of a folder holding source.exr, target.exr, depth.exr and mask.png."""
    from invsss.io import load_pair

    return load_pair(*(os.path.join(pair_dir, name) for name in ("source.exr", "target.exr", "depth.exr", "mask.png")))


def _compare(pair_dirs, title: str, settings: dict) -> None:
    """Each pair fitted with the CLI defaults under each of ``settings`` (name ->
    fit options), in one process; a short warm-up fit per pair and setting comes
    first so that no column pays for compilation."""
    print(f"bench_fit {title}: fit_pair with the CLI defaults; "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")
    first = next(iter(settings))
    header = (f"{'pair':22s} {'setting':12s} {'steps':>5s} {'seconds':>8s} {'sss_level':>16s} "
              f"{'correction':>16s} {'chi2 - ' + first:>15s} {'moved (sd)':>10s}")
    print(header)
    print("-" * len(header))
    totals = defaultdict(lambda: [0, 0.0])
    for pair_dir in pair_dirs:
        pair = read_pair_folder(pair_dir)
        results = {}
        for name, values in settings.items():
            options = values
            fit_pair(pair.source, pair.target, pair.depth, pair.mask, max_steps=2, **options)  # compile this setting
            t0 = time.perf_counter()
            results[name] = result = fit_pair(pair.source, pair.target, pair.depth, pair.mask, **options)
            seconds = time.perf_counter() - t0
            totals[name][0] += result.iterations
            totals[name][1] += seconds
            # chi^2 difference: the loss over its noise variance, summed over the mask.
            base = results[first]
            dof = float(np.sum(np.asarray(pair.mask) > 0))
            chi2 = (result.loss - base.loss) * dof / base.loss
            # Undetermined parameters (no standard error, e.g. correction on flat depth) are left out.
            moved = max((abs(float(result.values[k]) - float(base.values[k])) / float(base.stderr[k])
                         for k in ("sss_level", "correction") if base.stderr[k] is not None), default=np.nan)
            cells = [f"{result.values[k]:8.1f} +- " + ("undet." if result.stderr[k] is None else f"{result.stderr[k]:5.1f}")
                     for k in ("sss_level", "correction")]
            print(f"{os.path.basename(pair_dir.rstrip('/')):22s} {name:12s} {result.iterations:5d} {seconds:8.2f} "
                  f"{cells[0]:>16s} {cells[1]:>16s} {chi2:15.2f} {moved:10.2f}", flush=True)
    print("all: " + "; ".join(f"{k}: {n} steps, {t:.1f} s" for k, (n, t) in totals.items()))
    for name in list(settings)[1:]:
        print(f"{name} / {first}: steps {totals[name][0] / totals[first][0]:.2f}, "
              f"time {totals[name][1] / totals[first][1]:.2f}")


def stopping(pair_dirs) -> None:
    """The stall test of invsss.estimator.solve off and on."""
    _compare(pair_dirs, "--stopping (stall test off / on)", {
        "stall off": {"stall_test": False},
        "stall on": {"stall_test": True},
    })


def jacobian(pair_dirs) -> None:
    """The solvers' Jacobian by forward mode and by forward differences."""
    _compare(pair_dirs, "--jacobian (forward mode / forward differences)", {
        "forward-mode": {"solver_jacobian": "forward-mode"},
        "differences": {"solver_jacobian": "differences"},
    })


if __name__ == "__main__":
    main()
