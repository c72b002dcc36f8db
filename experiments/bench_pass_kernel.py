"""One directional pass: the XLA reference against the Pallas kernel (invsss.forward.pass_kernels).

For each square size and pass axis the script times, on JAX's default device:
the forward pass, its JVP with one tangent (image and footprint), with 8
tangents at once (``jax.jacfwd``-style, the estimator's Jacobian), and its VJP
(reverse mode), for the XLA reference and for the kernel at each ``--blocks``
tile; and the largest difference of each output from the reference. Footprints
are 2-9 px (a 1024-px face at the thesis's 940 nm profile) scaled with the size.
Times are medians of ``--repeats`` runs after a warm-up, with
``block_until_ready``; ``fwd queued`` is the forward pass's time per call when
``--repeats`` calls are dispatched at once and waited for once. The kernel runs compiled on a GPU only; elsewhere the
``pallas`` rows time its XLA lowering (the reference wrapped in the primitive).
The ``vjp`` of the ``pallas`` rows is the transpose that
:data:`invsss.forward.pass_kernels.KERNEL_ON_CUDA` picks: XLA's since the measurement in
docs/gpu.md, whose ``vjp`` column timed the Pallas transpose kernel.

Usage::

    python experiments/bench_pass_kernel.py [--sizes 256 1024 2048] [--repeats 20]
        [--blocks 8x128 4x128 16x64 2x256]
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

from invsss.forward.pass_kernels import directional_pass_kernel
from invsss.forward.passes import directional_pass_xla, tap_weights

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from bench_forward import queued_time  # noqa: E402


def scene(size: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    image = jnp.asarray(rng.random((size, size, 3)), jnp.float32)
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size - 0.5
    footprint = (2.0 + 7.0 * np.exp(-(x**2 + y**2) / 0.1)) * size / 1024
    mask = np.clip((0.45 - np.sqrt(x**2 + y**2)) * 40.0, 0.0, 1.0)
    return image, jnp.asarray(footprint, jnp.float32), jnp.asarray(mask, jnp.float32), rng


def median_ms(fn, *args, repeats: int) -> float:
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def functions(pass_fn, mask, axis, tangents_i, tangents_f, cotangent):
    weights = tap_weights()

    def forward(image, footprint):
        return pass_fn(image, footprint, mask, weights, axis)

    def jvp1(image, footprint):
        return jax.jvp(forward, (image, footprint), (tangents_i[0], tangents_f[0]))[1]

    def jvp8(image, footprint):
        return jax.vmap(lambda di, df: jax.jvp(forward, (image, footprint), (di, df))[1])(tangents_i, tangents_f)

    def vjp(image, footprint):
        return jax.vjp(forward, image, footprint)[1](cotangent)

    return {"forward": jax.jit(forward), "jvp x1": jax.jit(jvp1), "jvp x8": jax.jit(jvp8), "vjp": jax.jit(vjp)}


def _max_diff(a, b) -> float:
    return max(float(jnp.max(jnp.abs(x - y))) for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 1024, 2048])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--blocks", nargs="+", default=["8x128", "4x128", "16x64", "2x256"])
    args = parser.parse_args(argv)
    blocks = [tuple(int(v) for v in b.split("x")) for b in args.blocks]
    device = jax.devices()[0]
    print(f"bench_pass_kernel: jax {jax.__version__}, device {device} ({device.device_kind}); "
          f"ms, median of {args.repeats}; diff = max |kernel - XLA| over the outputs")
    kinds = ("forward", "jvp x1", "jvp x8", "vjp")
    header = (f"{'size':>5} {'axis':>4} {'path':<14}" + "".join(f"{k:>10}" for k in kinds)
              + f"{'fwd queued':>11}{'diff':>10}")
    print(header)
    print("-" * len(header))
    for size in args.sizes:
        image, footprint, mask, rng = scene(size)
        t_i = jnp.asarray(rng.standard_normal((8,) + image.shape), jnp.float32)
        t_f = jnp.asarray(rng.standard_normal((8,) + footprint.shape), jnp.float32)
        cot = jnp.asarray(rng.standard_normal(image.shape), jnp.float32)
        for axis in (1, 0):
            paths = [("xla", directional_pass_xla)] + [
                (f"pallas {b[0]}x{b[1]}",
                 lambda i, f, m, w, a, b=b: directional_pass_kernel(i, f, m, w, a, block=b))
                for b in blocks
            ]
            reference = None
            for name, fn in paths:
                fns = functions(fn, mask, axis, t_i, t_f, cot)
                try:
                    times = [median_ms(fns[k], image, footprint, repeats=args.repeats) for k in kinds]
                    queued = 1e3 * queued_time(fns["forward"], image, footprint, repeats=args.repeats)
                    outs = [fns[k](image, footprint) for k in kinds]
                except Exception as err:  # a tile Triton rejects: say so, go on
                    print(f"{size:>5} {axis:>4} {name:<14} failed: {type(err).__name__}: {str(err)[:200]}")
                    continue
                if reference is None:
                    reference, diff = outs, ""
                else:
                    diff = f"{_max_diff(outs, reference):10.1e}"
                print(f"{size:>5} {axis:>4} {name:<14}" + "".join(f"{t:10.3f}" for t in times)
                      + f"{queued:11.3f}{diff:>10}",
                      flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
