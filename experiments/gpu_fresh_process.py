"""Where a fresh process's seconds go: a 1024 x 1024 fit, cold, on a warm cache, verified.

Issue 52, item 4 (measurement only): a fresh process that fits on a warm
compiled-code cache took about 7 s on the GPU. This script runs the same
``fit_pair`` (the command line's defaults, on ``experiments/bench_fit.py``'s
model-made pair) in a row of fresh processes sharing one cache folder and splits
each process's wall time, from the parent's spawn to the child's exit:

``python start``
    from the parent's ``subprocess`` call to the child's first line;
``import ...``
    numpy, jax, invsss, its estimator and its readers, one row each;
``JAX backend start``
    the first ``jax.devices()`` (the CUDA client, and on a GPU the allocation
    of XLA's memory pool), unless an import did it already (then it says so);
``enable cache``, ``reading``
    :func:`invsss.runtime.compile_cache.enable_compile_cache`, and loading the
    pair from a ``.npz`` (made once, beforehand, by a process of its own);
``fit_pair``
    and its stages (as ``bench_fit --breakdown`` wraps them), the wait for the
    thread that compiles or loads the solver's step, and the executable cache's
    own work (:mod:`invsss.runtime.executable_cache`): the source fingerprint,
    the entry keys, reading and checksumming entries, the first-use trial in a
    child process, deserialising and loading, compiling on a miss, storing;
``trial child: ...``
    inside each first-use trial (:func:`invsss.runtime.executable_entries.try_in_child`):
    its start, imports, JAX backend, load and run, exit;
``JAX jit ...``
    the tracing, lowering, XLA compilation and persistent-cache reads that JAX
    itself reports (``jax.monitoring``) for everything, the executable cache's
    misses included;
``after fit_pair``, ``exit``
    printing the result, and the interpreter's and the GPU client's shutdown
    (the parent's clock at the child's exit minus the child's last timestamp).

Rows with ``[2nd]`` ran on the thread that prepares the solver's step beside
the start scan: they overlap the main thread's rows. The processes, in order:
``cold`` (empty cache), ``warm`` (the first process on the cache: it tries
each entry in a child process), ``verified`` and ``verified 2`` (later
processes: they load the verified entries directly), and ``no prealloc``
(another verified process with ``XLA_PYTHON_CLIENT_PREALLOCATE=false``, to
see what XLA's memory pool costs at start). With ``--importtime`` one more
verified process runs under ``python -X importtime`` and the slowest imports
are listed. Nothing in invsss is changed; the instrumentation wraps functions
from the outside, in the measured child processes only.

Usage::

    python experiments/gpu_fresh_process.py [--size 1024] [--importtime] [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

_T0_WALL = time.time()  # first line: the child's start, against the parent's spawn time
_T0 = time.perf_counter()

HERE = os.path.dirname(os.path.abspath(__file__))
SPAWN_VARIABLE = "GPU_FRESH_SPAWN"
TRIAL_TAG = "GPU_FRESH_TRIAL "

# The code the first-use trial's child runs (executable_entries._TRY), timed:
# the same call, with its phases written to stderr before "ok".
_TRY_TIMED = r"""
import os, sys, time, json
T = {"start": time.time() - float(os.environ.get("GPU_FRESH_SPAWN", "nan"))}
t = time.perf_counter()
def mark(name):
    global t
    now = time.perf_counter(); T[name] = T.get(name, 0.0) + now - t; t = now
import jax
mark("import jax")
import invsss.runtime.executable_entries as E
mark("import invsss")
jax.devices()
mark("JAX backend start")
from jax.experimental import serialize_executable as S
_deser = S.deserialize_and_load
def _timed_deser(*a, **k):
    mark("read + checksum + prepare + unpickle")
    out = _deser(*a, **k)
    mark("deserialize + load")
    return out
S.deserialize_and_load = _timed_deser
_block = jax.block_until_ready
def _timed_block(x):
    out = _block(x)
    mark("arguments + run")
    return out
jax.block_until_ready = _timed_block
E.try_entry(*sys.argv[1:5])
mark("rest")
T["end"] = time.time()
print("GPU_FRESH_TRIAL " + json.dumps(T), file=sys.stderr, flush=True)
print("ok", flush=True)
"""


# ------------------------------------------------------------------ the child


def _union(spans) -> float:
    """Seconds covered by at least one of the (start, end) spans."""
    total, end = 0.0, float("-inf")
    for a, b in sorted(spans):
        if b <= end:
            continue
        total += b - max(a, end)
        end = b
    return total


class _Recorder:
    """Seconds and calls per label; a label on a thread other than the main one gets ' [2nd]'."""

    def __init__(self):
        import threading

        self.main = threading.main_thread()
        self.seconds: dict = {}
        self.counts: dict = {}
        self.spans: dict = {}

    def add(self, label, start, end, thread=None):
        import threading

        if (thread or threading.current_thread()) is not self.main:
            label += " [2nd]"
        self.seconds[label] = self.seconds.get(label, 0.0) + end - start
        self.counts[label] = self.counts.get(label, 0) + 1
        self.spans.setdefault(label, []).append((start - _T0, end - _T0))

    def wrap(self, owner, name, label):
        import inspect

        static = isinstance(inspect.getattr_static(owner, name), staticmethod)
        inner = getattr(owner, name)

        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                self.add(label(*args, **kwargs) if callable(label) else label, start, time.perf_counter())

        timed.__wrapped__ = inner
        setattr(owner, name, staticmethod(timed) if static else timed)


def child(cache_dir: str, scene_path: str) -> None:
    phases = {"python start": _T0_WALL - float(os.environ.get(SPAWN_VARIABLE, "nan"))}
    t = [time.perf_counter()]

    def mark(name):
        now = time.perf_counter()
        phases[name] = now - t[0]
        t[0] = now

    import numpy as np

    mark("import numpy")
    import jax

    mark("import jax")
    import invsss

    mark("import invsss")
    import invsss.estimator
    import invsss.estimator.core as core_module
    import invsss.estimator.fit as fit_module
    import invsss.estimator.problem as problem_module
    import invsss.estimator.search as search_module
    import invsss.estimator.summary as summary_module

    mark("import invsss.estimator")
    import invsss.io  # noqa: F401  (what the command line loads to read a pair)

    mark("import invsss.io")
    try:
        from jax._src import xla_bridge

        started_by_import = bool(getattr(xla_bridge, "_backends", {}))
    except ImportError:
        started_by_import = None
    device = jax.devices()[0]
    mark("JAX backend start")
    from invsss.runtime import executable_cache as cache_module
    from invsss.runtime import executable_entries as entries_module
    from invsss.runtime.compile_cache import enable_compile_cache

    enable_compile_cache(cache_dir)
    mark("enable cache")
    with np.load(scene_path) as stored:
        pair = [stored[name] for name in ("source", "target", "depth", "mask")]
    mark("reading (.npz)")

    rec = _Recorder()
    # The fit's stages (as experiments/bench_fit.py --breakdown).
    rec.wrap(core_module, "build_problem", "build problem (with start scan)")
    rec.wrap(problem_module, "choose_starts", "start scan")
    rec.wrap(search_module, "run_solver", "solves")
    rec.wrap(summary_module, "gauss_newton_uncertainty", "covariance")
    rec.wrap(core_module, "summarise", "report (all)")
    rec.wrap(core_module.SolverCompilation, "wait", "wait for the solver-step thread")
    # The executable cache, from the outside.
    jit_class = cache_module.persistent_jit
    rec.wrap(cache_module, "_code_fingerprint", "cache: source fingerprint")
    rec.wrap(jit_class, "_file_key", "cache: entry key (incl. fingerprint)")
    keys: list = []  # (function, entry name): a key that changes between processes is a miss
    key_parts: dict = {}
    file_key = jit_class._file_key

    def noted_key(self, key, static):
        name = file_key(self, key, static)
        keys.append((self.fun.__name__, None if name is None else name[:12]))
        # What the key is made of, each part hashed: which one changed, if a key does.
        import hashlib

        def digest(value):
            try:
                return hashlib.sha256(cache_module._dumps(value, shared=False)).hexdigest()[:8]
            except Exception as err:  # noqa: BLE001
                return type(err).__name__

        in_tree, _, _, avals, settings = key
        key_parts.setdefault(self.fun.__name__, {
            "source+versions": cache_module._code_fingerprint()[:8], "settings": digest(settings),
            "settings (text)": repr(settings), "avals": digest(avals), "in_tree": digest(in_tree),
            "static": digest(static),
        })
        return name

    jit_class._file_key = noted_key
    rec.wrap(jit_class, "_load", "cache: load entry (all)")
    rec.wrap(cache_module, "read_private", "cache: read entry file")
    rec.wrap(cache_module, "unseal", "cache: checksum")
    rec.wrap(cache_module, "is_verified", "cache: verified record")
    rec.wrap(cache_module, "try_in_child", "cache: first-use trial (child)")
    rec.wrap(cache_module, "record_verified", "cache: write verified record")
    rec.wrap(cache_module, "prepare_runtime", "cache: prepare runtime")
    from jax.experimental import serialize_executable

    rec.wrap(serialize_executable, "deserialize_and_load", "cache: deserialize + load")
    rec.wrap(jit_class, "_compile", lambda self, *a: f"cache miss: trace+lower+compile {self.fun.__name__}")
    rec.wrap(jit_class, "_store", "cache: serialize + store")
    first_calls: dict = {}
    calls = jit_class.__call__

    def timed_call(self, *args):
        start = time.perf_counter()
        out = calls(self, *args)
        name = self.fun.__name__
        if name not in first_calls:
            first_calls[name] = time.perf_counter() - start
        return out

    jit_class.__call__ = timed_call
    # The trial's child: the same call, its phases timed (see _TRY_TIMED).
    trials = []
    real_run = subprocess.run

    class _Subprocess:
        def __getattr__(self, name):
            return getattr(subprocess, name)

        @staticmethod
        def run(command, *args, env=None, **kwargs):
            if len(command) > 2 and command[1] == "-c":
                command = [command[0], "-c", _TRY_TIMED, *command[3:]]
            env = dict(env if env is not None else os.environ)
            env[SPAWN_VARIABLE] = repr(time.time())
            done = real_run(command, *args, env=env, **kwargs)
            ended = time.time()
            for line in (done.stderr or b"").decode(errors="replace").splitlines():
                if line.startswith(TRIAL_TAG):
                    phases_child = json.loads(line[len(TRIAL_TAG):])
                    phases_child["exit"] = ended - phases_child.pop("end")
                    trials.append(phases_child)
            return done

    entries_module.subprocess = _Subprocess()
    # JAX's own compile events, for everything.
    from jax import monitoring

    kinds = {
        "/jax/core/compile/jaxpr_trace_duration": "JAX jit: trace",
        "/jax/core/compile/jaxpr_to_mlir_module_duration": "JAX jit: lower",
        "/jax/core/compile/backend_compile_duration": "JAX jit: XLA compile",
        "/jax/compilation_cache/cache_retrieval_time_sec": "JAX jit: persistent-cache reads",
    }
    jax_events: dict = {}
    jax_spans: list = []

    def on_duration(event, duration, **_):
        kind = kinds.get(event)
        if kind is not None:
            end = time.perf_counter()
            jax_spans.append((end - duration, end))
            seconds, n = jax_events.get(kind, (0.0, 0))
            jax_events[kind] = (seconds + duration, n + 1)

    monitoring.register_event_duration_secs_listener(on_duration)
    mark("instrumenting")

    result = fit_module.fit_pair(*pair)
    mark("fit_pair")
    record = {
        "phases": phases, "started_by_import": started_by_import,
        "device": f"{device.platform}: {device.device_kind}", "invsss": os.path.dirname(invsss.__file__),
        "stages": rec.seconds, "counts": rec.counts, "keys": sorted(set(keys)), "key_parts": key_parts, "first_calls": first_calls, "trials": trials,
        "jax": jax_events, "jax_wall": _union(jax_spans),
        "loss": float(result.loss), "iterations": int(result.iterations),
        "prealloc": os.environ.get("XLA_PYTHON_CLIENT_PREALLOCATE", "default"),
    }
    record["phases"]["after fit_pair"] = time.perf_counter() - t[0]
    record["end"] = time.time()
    print(json.dumps(record), flush=True)


# ------------------------------------------------------------------ the parent


def make_scene(size: int, path: str) -> None:
    """bench_fit's model-made pair, saved as float32 (its own process, so that the
    parent never starts JAX on the GPU while the measured children run)."""
    code = (
        "import sys, numpy as np; sys.path.insert(0, sys.argv[1]); import bench_fit; "
        "s, t, d, m = bench_fit.make_scene(int(sys.argv[2])); "
        "np.savez(sys.argv[3], source=s.astype(np.float32), target=t.astype(np.float32), "
        "depth=d.astype(np.float32), mask=m.astype(np.float32))"
    )
    env = dict(os.environ, XLA_PYTHON_CLIENT_PREALLOCATE="false")
    subprocess.run([sys.executable, "-c", code, HERE, str(size), path], check=True, env=env)


def run_child(cache_dir: str, scene: str, extra_env=None, importtime=False) -> dict:
    command = [sys.executable, *(["-X", "importtime"] if importtime else []), os.path.abspath(__file__),
               "--child", cache_dir, "--scene", scene]
    env = {k: v for k, v in os.environ.items() if k != "INVSSS_NO_CACHE"}
    env.update(extra_env or {})
    env[SPAWN_VARIABLE] = repr(time.time())
    start = time.time()
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    ended = time.time()
    if done.returncode != 0:
        raise SystemExit(f"gpu_fresh_process: a child failed (exit status {done.returncode}):\n"
                         + done.stderr[-4000:])
    record = json.loads(done.stdout.strip().splitlines()[-1])
    record["wall"] = ended - start
    record["phases"]["exit"] = ended - record.pop("end")
    if importtime:
        record["importtime"] = done.stderr
    return record


def slowest_imports(text: str, top: int = 14) -> list[tuple[float, float, str]]:
    """(cumulative s, self s, module) of the slowest imports listed by -X importtime,
    top-level packages and their direct submodules only."""
    rows = []
    for line in text.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        parts = line.split(":", 1)[1].split("|")
        if len(parts) != 3:
            continue
        raw = parts[2].rstrip()
        depth = (len(raw) - len(raw.lstrip()) - 1) // 2
        if depth <= 1:
            rows.append((int(parts[1]) / 1e6, int(parts[0]) / 1e6, "  " * depth + raw.strip()))
    return sorted(rows, reverse=True)[:top]


def import_self_by_package(text: str, top: int = 14) -> list[tuple[float, str]]:
    """Self seconds of every import listed by -X importtime, summed by top-level package."""
    totals: dict = {}
    for line in text.splitlines():
        parts = line.split(":", 1)[1].split("|") if line.startswith("import time:") else []
        if len(parts) != 3 or "cumulative" in line:
            continue
        package = parts[2].strip().split(".")[0]
        totals[package] = totals.get(package, 0.0) + int(parts[0]) / 1e6
    return sorted(((v, k) for k, v in totals.items()), reverse=True)[:top]


def table(columns: dict) -> list[str]:
    names = list(columns)
    first = next(iter(columns.values()))
    lines = []
    header = f"{'phase':<46}" + "".join(f"{n:>14}" for n in names)
    lines += [header, "-" * len(header)]

    def row(label, cells):
        lines.append(f"{label:<46}" + "".join(f"{c:>14}" for c in cells))

    def seconds(value, count=None):
        if value is None:
            return "-"
        return f"{value:.2f}" + (f" ({count})" if count is not None else "")

    row("whole process (spawn to exit)", [seconds(c["wall"]) for c in columns.values()])
    phase_names = []
    for c in columns.values():
        phase_names += [p for p in c["phases"] if p not in phase_names]
    for phase in phase_names:
        row("  " + phase, [seconds(c["phases"].get(phase)) for c in columns.values()])
    row("  (sum of the rows above)", [seconds(sum(c["phases"].values())) for c in columns.values()])
    row("backend started by an import", ["yes" if c["started_by_import"] else "no" for c in columns.values()])
    stage_names = []
    for c in columns.values():
        stage_names += [s for s in c["stages"] if s not in stage_names]
    lines.append("inside fit_pair: seconds (calls); [2nd]: on the thread beside the start scan")
    for stage in stage_names:
        row("  " + stage[:44], [seconds(c["stages"][stage], c["counts"][stage]) if stage in c["stages"] else "-"
                                for c in columns.values()])
    functions = []
    for c in columns.values():
        functions += [f for f in c["first_calls"] if f not in functions]
    lines.append("first call of each cached function (load or compile, and its first run)")
    for fun in functions:
        row("  " + fun, [seconds(c["first_calls"].get(fun)) for c in columns.values()])
    trial_names = []
    for c in columns.values():
        for trial in c["trials"]:
            trial_names += [p for p in trial if p not in trial_names]
    if trial_names:
        lines.append("inside the first-use trials' child processes (summed over trials)")
        row("  trials", [str(len(c["trials"])) for c in columns.values()])
        for phase in trial_names:
            row("  trial child: " + phase, [seconds(sum(t.get(phase, 0.0) for t in c["trials"]))
                                            if c["trials"] else "-" for c in columns.values()])
    kinds = []
    for c in columns.values():
        kinds += [k for k in c["jax"] if k not in kinds]
    lines.append("JAX's own compile events (all functions): seconds (events)")
    for kind in kinds:
        row("  " + kind, [seconds(*c["jax"][kind]) if kind in c["jax"] else "-" for c in columns.values()])
    row("  JAX jit events, wall time covered", [seconds(c["jax_wall"]) for c in columns.values()])
    row("entries keyed (distinct)", [str(len(c["keys"])) for c in columns.values()])
    row("  same keys as the cold process", ["yes" if c["keys"] == first["keys"] else "NO"
                                            for c in columns.values()])
    row("fit: iterations", [str(c["iterations"]) for c in columns.values()])
    row("fit: loss", [f"{c['loss']:.4e}" for c in columns.values()])
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=int, default=1024, help="the pair's side in pixels (default 1024)")
    parser.add_argument("--importtime", action="store_true",
                        help="one more verified process under python -X importtime; list the slowest imports")
    parser.add_argument("--no-prealloc-run", action="store_true",
                        help="leave out the verified process with XLA_PYTHON_CLIENT_PREALLOCATE=false")
    parser.add_argument("--json", default=None, help="also write every process's record here")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--scene", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child is not None:
        child(args.child, args.scene)
        return
    with tempfile.TemporaryDirectory(prefix="invsss-fresh-") as scratch:
        scene = os.path.join(scratch, "scene.npz")
        cache = os.path.join(scratch, "cache")
        start = time.time()
        make_scene(args.size, scene)
        print(f"gpu_fresh_process: made the {args.size} x {args.size} pair in {time.time() - start:.1f} s "
              f"(its own process, not counted below)", flush=True)
        columns = {}
        plan = [("cold", None), ("warm", None), ("verified", None), ("verified 2", None)]
        if not args.no_prealloc_run:
            plan.append(("no prealloc", {"XLA_PYTHON_CLIENT_PREALLOCATE": "false"}))
        for name, env in plan:
            columns[name] = run_child(cache, scene, env)
            print(f"  {name}: {columns[name]['wall']:.2f} s", flush=True)
        imported = run_child(cache, scene, importtime=True) if args.importtime else None
    if args.json:  # before the table: a failure there keeps the records
        with open(args.json, "w") as file:
            json.dump({**columns, **({"importtime": {k: v for k, v in imported.items() if k != "importtime"}}
                                     if imported else {})}, file, indent=1)
    first = next(iter(columns.values()))
    print(f"gpu_fresh_process: fit_pair (command-line defaults) of a model-made {args.size} x {args.size} pair, "
          f"fresh processes on one cache folder; {os.cpu_count()} CPUs; JAX device {first['device']}; "
          f"python {sys.version.split()[0]}; invsss from {first['invsss']}; seconds")
    print("\n".join(table(columns)))
    if imported is not None:
        print(f"python -X importtime, one more verified process ({imported['wall']:.2f} s, "
              f"imports inflated by the tracing): slowest top-level imports, cumulative and self seconds")
        for cumulative, own, name in slowest_imports(imported["importtime"]):
            print(f"  {cumulative:7.3f} {own:7.3f}  {name}")
        print("the same imports' self seconds summed by top-level package")
        for own, package in import_self_by_package(imported["importtime"]):
            print(f"  {own:7.3f}  {package}")


if __name__ == "__main__":
    main()
