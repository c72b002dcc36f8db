#!/usr/bin/env bash
# Everything issue 35 measures on a lent GPU, in one call, each part with its own
# time limit so that one hang does not lose the rest. Run from the repository
# root (or a copy of it) with OUT set to a folder for the logs; wheels of the
# packages the machine lacks may lie in ./wheels (installed into /tmp/site).
#
#   OUT=/tmp/out bash experiments/gpu_session.sh
#
# Parts, most important first: environment; the GPU tests (pytest -m gpu); one
# pass at 1024 px, XLA against the kernel at several tiles; the models' forward
# and value+grad at 256, 1024 and 2048 px (both pass implementations, the scan
# unrolled or not); the bundled pair's command-line fit cold and warm (kernels,
# then XLA passes); a model-made 1024 x 1024 pair's fit cold and warm with the
# per-step host/device split; then, for ratios, the machine's CPU: the forward
# benchmark, and the command-line fit limited to 2 cores as on the project's
# machines; last the one-pass benchmark at 256 and 2048 px and the 1024 x 1024
# fit with XLA passes. All output goes to $OUT/session.log, the fits' own logs
# to $OUT/fit_logs.txt. docs/gpu.md holds what it printed on an H100.
set -o pipefail
OUT=${OUT:-/tmp/invsss-gpu-session}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
if [ -d wheels ]; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site wheels/*.whl \
        > "$OUT/pip.log" 2>&1 || echo "wheel install failed (see pip.log)"
    export PYTHONPATH=$PWD:/tmp/site:${PYTHONPATH:-}
else
    export PYTHONPATH=$PWD:${PYTHONPATH:-}
fi
PAIR=data_synthetic/fran_front
CACHE=$(mktemp -d /tmp/invsss-cache-XXXX)

part() {  # part NAME SECONDS COMMAND...: run with a limit, append to $OUT/session.log
    local name=$1 limit=$2
    shift 2
    echo "===== $name (limit ${limit}s) $(date -u +%H:%M:%S)" | tee -a "$OUT/session.log"
    local t0=$SECONDS
    timeout -k 5 "$limit" "$@" 2>&1 | tee -a "$OUT/session.log"
    local rc=$?
    echo "===== $name: rc=$rc, $((SECONDS - t0)) s" | tee -a "$OUT/session.log"
}

cli_fit() {  # cli_fit LABEL: one command-line fit of the bundled pair, its wall seconds
    local label=$1 t0 dir
    dir="/tmp/fit-${label// /_}"
    t0=$EPOCHREALTIME
    python3 -m invsss fit --source $PAIR/source.exr --target $PAIR/target.exr --depth $PAIR/depth.exr \
        --mask $PAIR/mask.png --out "$dir" --overwrite > "$dir.log" 2>&1
    local rc=$?
    printf '%-28s %8.2f s  rc=%d  %s\n' "$label" "$(awk "BEGIN {print $EPOCHREALTIME - $t0}")" $rc \
        "$(grep -o '"loss": [0-9.e+-]*' "$dir/params.json" 2>/dev/null | head -1)"
    { echo "----- $label"; tail -25 "$dir.log"; } >> "$OUT/fit_logs.txt"
}
export -f cli_fit
export PAIR OUT
PIN=""
command -v taskset > /dev/null && PIN="taskset -c 0,1"

part env 60 bash -c 'date -u; nvidia-smi -L; nvidia-smi --query-gpu=name,clocks.sm,clocks.mem,temperature.gpu,utilization.gpu --format=csv;
    nproc; python3 -c "import jax, jaxlib, equinox, optimistix; print(\"jax\", jax.__version__, \"jaxlib\", jaxlib.__version__, \"equinox\", equinox.__version__, \"optimistix\", optimistix.__version__); print(jax.devices(), jax.default_backend())";
    python3 -c "import invsss, invsss.io, invsss.pass_kernels as k; print(invsss.__file__); import jax.numpy as jnp; print(\"kernel on:\", k.kernel_enabled(jnp.zeros((8,8,3))))"'

part gpu_tests 60 python3 -m pytest -q -p no:cacheprovider -m gpu tests/test_pass_kernels.py -rA

part pass_1024 80 python3 experiments/bench_pass_kernel.py --sizes 1024 --repeats 20 --blocks 8x128 4x128 16x64 2x256

part forward_gpu 150 python3 experiments/bench_forward.py --sizes 256 1024 2048 --repeats 20 --device gpu \
    --passes xla pallas pallas+unroll

part cli_fit_gpu 100 bash -c 'export INVSSS_CACHE_DIR='"$CACHE"'; cli_fit "gpu cold"; cli_fit "gpu warm";
    export INVSSS_PASS_KERNEL=xla; cli_fit "gpu XLA passes cold"; cli_fit "gpu XLA passes warm"'

part fit_1024_gpu 130 python3 experiments/bench_fit.py --breakdown synthetic:1024

part forward_cpu 45 env JAX_PLATFORMS=cpu python3 experiments/bench_forward.py --sizes 256 1024 --repeats 3 \
    --device cpu --passes xla --no-torch

CACHE2=$(mktemp -d /tmp/invsss-cache-XXXX)
part cli_fit_cpu2 45 bash -c 'export INVSSS_CACHE_DIR='"$CACHE2"' JAX_PLATFORMS=cpu;
    echo "pinned with: '"${PIN:-nothing, no taskset}"'";
    '"$PIN"' bash -c "cli_fit \"cpu 2 cores cold\"; cli_fit \"cpu 2 cores warm\""'

part pass_sizes 80 python3 experiments/bench_pass_kernel.py --sizes 256 2048 --repeats 20 --blocks 8x128

part fit_1024_gpu_xla 130 env INVSSS_PASS_KERNEL=xla python3 experiments/bench_fit.py --breakdown synthetic:1024

echo "===== done $(date -u +%H:%M:%S)"
