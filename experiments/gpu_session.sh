#!/usr/bin/env bash
# Everything issues 35 and 52 measure on a lent GPU, in one call. Each part has
# its own time limit, cut further so that the whole script ends by $DEADLINE
# seconds (default 530) and one hang does not lose the rest. Run from the
# repository root (or a copy of it) with OUT set to a folder for the logs;
# wheels of the packages the machine lacks may lie in ./.whl (installed into
# /tmp/site). PARTS, a space-separated list of part names, runs only those.
#
#   OUT=/tmp/out bash experiments/gpu_session.sh
#   OUT=/tmp/out DEADLINE=300 PARTS="env gpu_tests fresh" bash experiments/gpu_session.sh
#
# Parts, most important first:
#   env          the machine, the libraries, which pass and loop the fit uses;
#   gpu_tests    the GPU tests (the ones pytest -m gpu selects: the compiled
#                kernels against the reference, values, JVP and the XLA
#                transpose's VJP) and the stepping-ahead loop, one line a test;
#   forward      the sog model's forward and value+grad at 1024 and 256 px,
#                reference passes against the kernels (the shipped default,
#                XLA's transpose for reverse mode) and the kernels with the scan
#                unrolled, with each one's distance from the reference
#                (bench_forward);
#   fresh        where a fresh process's seconds go, cold, warm and verified
#                cache, 1024 x 1024 (gpu_fresh_process.py; $OUT/fresh.json);
#   fit_1024     a model-made 1024 x 1024 pair's fit: cold, 2nd fit, warm cache,
#                verified cache (bench_fit --breakdown), stepping ahead;
#   cli_gpu      the bundled pair's command-line fit: cold, warm, verified;
#   cli_cpu2     the same on this machine's CPU pinned to 2 cores;
#   pass_1024    one pass, reference against the kernel (bench_pass_kernel);
#   quick_tier   the README's test command on the GPU backend;
#   fit_1024_plain  fit_1024's cold process only, with the plain loop;
#   fit_1024_unroll fit_1024's cold process with the passes' scan unrolled.
# All output goes to $OUT/session.log, the command-line fits' logs to
# $OUT/fit_logs.txt, the test run's to $OUT/quick_tier.log.
set -o pipefail
OUT=${OUT:-/tmp/invsss-gpu-session}
DEADLINE=${DEADLINE:-530}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
if [ -d .whl ]; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
        > "$OUT/pip.log" 2>&1 || echo "wheel install failed (see pip.log)"
    export PYTHONPATH=$PWD:/tmp/site:${PYTHONPATH:-}
else
    export PYTHONPATH=$PWD:${PYTHONPATH:-}
fi
PAIR=data_synthetic/fran_front

part() {  # part NAME SECONDS COMMAND...: run with a limit, append to $OUT/session.log
    local name=$1 limit=$2 left=$((DEADLINE - SECONDS))
    shift 2
    if [ -n "${PARTS:-}" ] && [[ " $PARTS " != *" $name "* ]]; then
        return
    fi
    if [ "$left" -lt 15 ]; then
        echo "===== $name: skipped, ${left} s left" | tee -a "$OUT/session.log"
        return
    fi
    [ "$limit" -gt "$left" ] && limit=$left
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

part env 40 bash -c 'date -u; nvidia-smi -L; nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.mem,temperature.gpu --format=csv;
    nproc; python3 -c "import jax, jaxlib, equinox, optimistix; print(\"jax\", jax.__version__, \"jaxlib\", jaxlib.__version__, \"equinox\", equinox.__version__, \"optimistix\", optimistix.__version__); print(jax.devices(), jax.default_backend())";
    python3 -c "import invsss, invsss.io, jax.numpy as jnp; from invsss.forward import pass_kernels as k; from invsss.estimator.solve import step_ahead; print(invsss.__file__); print(\"kernel on:\", k.kernel_enabled(jnp.zeros((8,8,3))), \"step ahead:\", step_ahead())"'

part gpu_tests 80 python3 -m pytest -v -p no:cacheprovider -m "gpu or not slow" tests/test_pass_kernels.py \
    tests/test_step_ahead.py -rfEs

part forward 80 python3 experiments/bench_forward.py --sizes 1024 256 --repeats 20 --device gpu \
    --passes xla pallas pallas+unroll --no-torch

part fresh 130 python3 experiments/gpu_fresh_process.py --size 1024 --importtime --json "$OUT/fresh.json"

part fit_1024 90 python3 experiments/bench_fit.py --breakdown synthetic:1024

CACHE=$(mktemp -d /tmp/invsss-cache-XXXX)
part cli_gpu 50 bash -c 'export INVSSS_CACHE_DIR='"$CACHE"'; cli_fit "gpu cold"; cli_fit "gpu warm"; cli_fit "gpu verified"'

CACHE2=$(mktemp -d /tmp/invsss-cache-XXXX)
part cli_cpu2 50 bash -c 'export INVSSS_CACHE_DIR='"$CACHE2"' JAX_PLATFORMS=cpu;
    echo "pinned with: '"${PIN:-nothing, no taskset}"'";
    '"$PIN"' bash -c "cli_fit \"cpu 2 cores cold\"; cli_fit \"cpu 2 cores warm\"; cli_fit \"cpu 2 cores verified\""'

part pass_1024 60 python3 experiments/bench_pass_kernel.py --sizes 1024 --repeats 20 --blocks 8x128 4x128

part quick_tier 130 bash -c 'XLA_PYTHON_CLIENT_PREALLOCATE=false python3 -m pytest -q -p no:cacheprovider \
    -n 6 -m "not slow" --continue-on-collection-errors -rfE > "$OUT/quick_tier.log" 2>&1; rc=$?; tail -40 "$OUT/quick_tier.log"; exit $rc'

part fit_1024_plain 40 env INVSSS_STEP_AHEAD=0 python3 experiments/bench_fit.py --breakdown synthetic:1024 --cold-only

part fit_1024_unroll 40 env INVSSS_SCAN_UNROLL=1 python3 experiments/bench_fit.py --breakdown synthetic:1024 --cold-only

echo "===== done $(date -u +%H:%M:%S), ${SECONDS} s"
