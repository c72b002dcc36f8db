"""Forward and gradient speed of the screen-space models: JAX against the PyTorch twin.

For each model and image size the script times, on one device per framework:

``forward``
    one render of an (S, S, 3) float32 image (the pure model function; the
    checked :func:`invsss.render` entry point adds NumPy validation on the host);
``value+grad``
    a scalar loss ``mean((render(p) - target)^2)`` and its gradient with respect
    to every parameter (``sss_level``, ``correction``, ``maxdd``, the K weights
    and the K variances): ``jax.value_and_grad`` against ``loss.backward()``;
``compile``
    for JAX, the time to lower and compile each function ahead of time (XLA);
    PyTorch runs eagerly and has none;
``queued``
    for JAX, the time per call when ``--repeats`` calls are dispatched back to
    back and waited for once: the host's dispatch of one call overlaps the
    device's work on the one before, so on a GPU this is close to the device's
    own time per call, while the ``forward`` and ``value+grad`` columns (one
    call, waited for) add the host's dispatch and the round trip to it.

``--passes xla pallas`` times the JAX rows once per implementation of the
directional pass (:mod:`invsss.forward.pass_kernels`: the XLA reference, the Pallas
kernel; ``auto``, the default, is what the backend picks; ``+unroll`` after
either also unrolls the models' scan over the passes, ``INVSSS_SCAN_UNROLL=1``) and prints how far
each one's forward image and gradient lie from the first one's. ``--no-torch``
leaves the PyTorch rows out.

Times are medians over ``--repeats`` runs after a warm-up run, with
``block_until_ready`` (JAX) and ``torch.cuda.synchronize`` (PyTorch on a GPU)
so that asynchronous dispatch is not mistaken for speed. The profile is the
thesis's five-Gaussian 940 nm fit (Table 5.1); the scene is a shaded bulge of
about 100 mm of relief 500 mm from a camera whose focal length is the image
width, so blur footprints grow with resolution as they would in a renderer.

Usage::

    python experiments/bench_forward.py [--sizes 256 512 1024] [--repeats 5]
        [--models sog thesis separable] [--device auto|cpu|gpu] [--torch-threads N]
        [--passes auto|xla|pallas[+unroll] ...] [--no-torch]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import invsss
from invsss.forward.models import MODEL_NAMES, get_model, resolve_tap_weights
from invsss.forward.screen_space import LAYOUT_RENDERERS

# The thesis's 940 nm forearm fit (its Table 5.1, docs/model.md, section 4).
THESIS_VARIANCES = [8.749, 2.099, 0.549, 0.5574, 1.194]
THESIS_WEIGHTS = [0.1478, 0.1323, 0.0004, 0.0527, 0.090]


def layout_renderer(model: str, renderers: dict):
    """The pure per-layout renderer of ``model`` (JAX or torch table) with its default taps bound."""
    entry = get_model(model)
    render_layout = renderers[entry.layout]
    tap_w = resolve_tap_weights(entry)  # None for the kernel layout, which ignores it

    def render_model(image, depth, mask, params):
        return render_layout(image, depth, mask, params, tap_w)

    return render_model


def make_scene(size: int, seed: int = 0):
    """Image (S, S, 3), target (S, S, 3), depth (S, S) in mm, mask (S, S); float32."""
    rng = np.random.default_rng(seed)
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size - 0.5
    r2 = x**2 + y**2
    depth = 500.0 - 100.0 * np.exp(-r2 / 0.08)
    shade = 0.3 + 0.7 * np.exp(-r2 / 0.15)
    texture = 1.0 + 0.2 * rng.standard_normal((size, size, 3))
    image = shade[..., None] * texture * np.array([0.8, 0.55, 0.45])
    target = image * 0.9 + 0.02
    mask = np.clip((0.45 - np.sqrt(r2)) * 40.0, 0.0, 1.0)
    return tuple(a.astype(np.float32) for a in (image, target, depth, mask))


def scene_params(size: int) -> dict:
    # sss_level: the focal length in pixels of a ~53 degree camera, so s = L / d px/mm.
    return dict(sss_level=float(size), correction=20.0, maxdd=1.0,
                weights=THESIS_WEIGHTS, variances=THESIS_VARIANCES)


def median_time(run, repeats: int) -> float:
    run()  # warm-up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def queued_time(fn, *args, repeats: int) -> float:
    """Seconds per call of ``fn(*args)`` when ``repeats`` calls are dispatched at once
    and waited for once: on a GPU the host's dispatch then overlaps the device's
    work, so this is near the device's own time per call.

    The best of three such batches: the first may still meet a cold cache or a
    clock that has not ramped up.
    """
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        jax.block_until_ready([fn(*args) for _ in range(repeats)])
        best = min(best, (time.perf_counter() - start) / repeats)
    return best


# ---------------------------------------------------------------------- JAX


def jax_device(kind: str):
    if kind == "auto":
        return jax.devices()[0]
    try:
        return jax.devices("gpu" if kind == "gpu" else "cpu")[0]
    except RuntimeError as err:
        raise SystemExit(f"bench_forward: no JAX {kind} device ({err})") from None


def bench_jax(model: str, size: int, repeats: int, device, passes: str = "auto") -> dict:
    """Times (and the forward image and gradient, for agreement) of one JAX row.

    ``passes`` sets ``INVSSS_PASS_KERNEL`` while the functions are traced,
    which is when :func:`invsss.forward.pass_kernels.kernel_enabled` is read.
    """
    from invsss.forward.pass_kernels import PASS_KERNEL_VARIABLE

    kernel, _, unroll = passes.partition("+")
    settings = {PASS_KERNEL_VARIABLE: kernel, "INVSSS_SCAN_UNROLL": "1" if unroll == "unroll" else "0"}
    saved = {name: os.environ.get(name) for name in settings}
    os.environ.update(settings)
    try:
        return _bench_jax(model, size, repeats, device)
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _bench_jax(model: str, size: int, repeats: int, device) -> dict:
    image, target, depth, mask = (jax.device_put(a, device) for a in make_scene(size))
    params = jax.device_put(invsss.SSSParams(**scene_params(size)), device)
    render_model = layout_renderer(model, LAYOUT_RENDERERS)

    def forward(p):
        return render_model(image, depth, mask, p)

    def loss(p):
        return jnp.mean((render_model(image, depth, mask, p) - target) ** 2)

    row = {}
    for name, fn in (("forward", forward), ("value+grad", jax.value_and_grad(loss))):
        start = time.perf_counter()
        compiled = jax.jit(fn).lower(params).compile()
        row[f"{name} compile"] = time.perf_counter() - start
        row[name] = median_time(lambda: jax.block_until_ready(compiled(params)), repeats)
        row[f"{name} queued"] = queued_time(compiled, params, repeats=repeats)
        row[f"{name} result"] = jax.device_get(compiled(params))
    return row


def _agreement(row: dict, first: dict) -> tuple[float, float]:
    """Largest |difference| of the forward image, and of the gradient relative to its largest entry."""
    image = float(np.max(np.abs(row["forward result"] - first["forward result"])))
    grad, ref = (jax.tree_util.tree_leaves(r["value+grad result"][1]) for r in (row, first))
    rel = max(float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-30)) for a, b in zip(grad, ref))
    return image, rel


# -------------------------------------------------------------------- PyTorch


def torch_device(kind: str):
    import torch

    if kind == "cpu" or (kind == "auto" and not torch.cuda.is_available()):
        return torch.device("cpu")
    if not torch.cuda.is_available():
        raise SystemExit("bench_forward: --device gpu, but torch has no CUDA device")
    return torch.device("cuda")


def bench_torch(model: str, size: int, repeats: int, device) -> dict:
    import torch

    import invsss.torch as itorch

    from invsss.torch.screen_space import LAYOUT_RENDERERS as TORCH_LAYOUT_RENDERERS

    render_model = layout_renderer(model, TORCH_LAYOUT_RENDERERS)
    image, target, depth, mask = (torch.as_tensor(a, device=device) for a in make_scene(size))
    values = scene_params(size)

    def leaf(v):
        return torch.tensor(v, dtype=torch.float32, device=device, requires_grad=True)

    def sync():
        if device.type == "cuda":
            torch.cuda.synchronize()

    fixed = itorch.SSSParams(**values).to(torch.float32, device)

    def forward():
        with torch.no_grad():
            render_model(image, depth, mask, fixed)
        sync()

    def value_and_grad():
        leaves = {k: leaf(v) for k, v in values.items()}
        loss = torch.mean((render_model(image, depth, mask, itorch.SSSParams(**leaves)) - target) ** 2)
        loss.backward()
        _ = [leaves[k].grad for k in leaves]
        sync()

    return {
        "forward": median_time(forward, repeats),
        "value+grad": median_time(value_and_grad, repeats),
    }


# ---------------------------------------------------------------------- main


def _ms(seconds) -> str:
    return f"{'-':>10}" if seconds is None else f"{1e3 * seconds:10.3f}"


def _s(seconds) -> str:
    return "-" if seconds is None else f"{seconds:8.2f}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 512, 1024],
                        help="square image sizes in pixels (default: 256 512 1024)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per cell (default: 5)")
    parser.add_argument("--models", nargs="+", choices=MODEL_NAMES, default=["sog"],
                        help="screen-space models (default: sog)")
    parser.add_argument("--device", choices=("auto", "cpu", "gpu"), default="auto",
                        help="auto: the GPU when both frameworks have one, else the CPU")
    parser.add_argument("--torch-threads", type=int, default=None, metavar="N",
                        help="torch.set_num_threads(N) for CPU runs (default: torch's choice); "
                        "on a machine shared with other jobs, 1 avoids OpenMP threads "
                        "spinning against each other")
    parser.add_argument("--passes", nargs="+", default=["auto"],
                        choices=[k + u for k in ("auto", "xla", "pallas") for u in ("", "+unroll")],
                        help="directional pass implementations for the JAX rows (default: auto); "
                        "agreement is measured against the first")
    parser.add_argument("--no-torch", action="store_true", help="leave the PyTorch rows out")
    args = parser.parse_args(argv)

    jdev = jax_device(args.device)
    try:
        if args.no_torch:
            raise ImportError("--no-torch")
        import torch

        import invsss.torch  # noqa: F401

        tdev = torch_device(args.device)
        if args.torch_threads:
            torch.set_num_threads(args.torch_threads)
        torch_note = f"torch {torch.__version__}, device {tdev}, {torch.get_num_threads()} threads"
    except ImportError as err:
        tdev = None
        torch_note = f"PyTorch rows skipped: invsss.torch is not importable ({err})"

    print(f"bench_forward: {platform.node()} ({os.cpu_count()} CPUs), python {platform.python_version()}")
    print(f"  jax {jax.__version__}, backend {jax.default_backend()}, device {jdev} ({jdev.device_kind})")
    print(f"  {torch_note}")
    print(f"  float32, 3 channels, {len(THESIS_VARIANCES)} Gaussians (thesis Table 5.1), "
          f"median of {args.repeats} after a warm-up; queued = per call of {args.repeats} "
          f"dispatched at once (best of 3); compile = JAX ahead-of-time lower+compile")
    print()
    header = (f"{'model':<10} {'size':>5} {'framework':<18} {'forward ms':>10} {'v+grad ms':>10} "
              f"{'fwd queued':>10} {'v+g queued':>10} {'fwd compile s':>13} {'v+g compile s':>13} {'max|d fwd|':>10} {'grad rel d':>10}")
    print(header)
    print("-" * len(header))
    for model in args.models:
        for size in args.sizes:
            rows = [(f"jax/{passes}", bench_jax(model, size, args.repeats, jdev, passes))
                    for passes in args.passes]
            if tdev is not None:
                rows.append(("torch", bench_torch(model, size, args.repeats, tdev)))
            first = rows[0][1]
            for framework, row in rows:
                agree = ("", "")
                if "forward result" in row and row is not first:
                    agree = tuple(f"{x:10.1e}" for x in _agreement(row, first))
                print(f"{model:<10} {size:>5} {framework:<18} {_ms(row['forward'])} "
                      f"{_ms(row['value+grad'])} {_ms(row.get('forward queued'))} "
                      f"{_ms(row.get('value+grad queued'))} {_s(row.get('forward compile')):>13} "
                      f"{_s(row.get('value+grad compile')):>13} {agree[0]:>10} {agree[1]:>10}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
