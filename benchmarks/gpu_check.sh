#!/usr/bin/env bash
# The GPU checks, in one go (a lent GPU machine has little time: see RESULTS.md).
#
#   bash benchmarks/gpu_check.sh [OUTDIR]
#
# Runs, each step time-boxed so a slow one cannot starve the rest:
#   1. the machine and JAX's devices;
#   2. bench_execution.py: kinematic marker evaluations per second, and the
#      largest difference from MuJoCo C (float32 products: cgda_jax.numerics);
#   3. the tests that exercise devices, sharding and MJX (the same code on a GPU);
#   4. bench_dynamic.py: MJX physics at P = 1,024 / 4,096 / 16,384 against
#      mujoco.rollout on every CPU core (the GPU rows of "Dynamic execution");
#   5. bench_trials.py: 30 IE trials in one batched call vs 30 calls.
# The quick steps come first: on the first try (an H200, 2026-12-04) steps 4 and 5
# ran past their limits before printing a row.
# Logs go to OUTDIR (default benchmarks/out) as gpu_check.log, with the benchmarks'
# JSON files packed in bench_json.tgz.
# Where packages are missing (a machine without network), put their wheels in .whl/
# first; they are installed to /tmp/site.
set -uo pipefail
cd "$(dirname "$0")/.."
OUTDIR="${1:-benchmarks/out}"
mkdir -p "$OUTDIR"
LOG="$OUTDIR/gpu_check.log"
export PYTHONUNBUFFERED=1 PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir \
    --upgrade --target /tmp/site .whl/*.whl && export PYTHONPATH="$PYTHONPATH:/tmp/site"
fi
step() {  # step SECONDS NAME COMMAND...
  local limit=$1 name=$2; shift 2
  echo "=== $name (limit ${limit} s) $(date -u +%T)" | tee -a "$LOG"
  local t0=$SECONDS
  timeout -k 5 "$limit" "$@" 2>&1 | tee -a "$LOG"
  echo "=== $name: exit ${PIPESTATUS[0]} after $((SECONDS - t0)) s" | tee -a "$LOG"
}
step 60 machine bash -c 'nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv;
  python3 -c "import jax, mujoco, mujoco.mjx, evosax, cgda_jax.experiment, cgda_jax.cli;
print(\"jax\", jax.__version__, jax.devices(), \"mujoco\", mujoco.__version__)"'
step "${EXECUTION_S:-60}" bench_execution python3 benchmarks/bench_execution.py \
  --pops 1024 16384 131072 --repeats 3
PER_TEST=$(python3 -c "import pytest_timeout" 2>/dev/null && echo --timeout=90)
step "${TESTS_S:-150}" tests python3 -m pytest -q -p no:cacheprovider $PER_TEST \
  tests/test_sharding.py tests/test_mjx_step.py tests/test_trials_batching.py \
  tests/test_physics.py
step "${DYNAMIC_S:-220}" bench_dynamic python3 benchmarks/bench_dynamic.py --pops \
  --mjx-pops 1024 4096 16384 --repeats 2
step "${TRIALS_S:-100}" bench_trials python3 benchmarks/bench_trials.py --repeats 2
# the benchmarks' JSON (exclusions before the folder: GNU tar's are positional),
# written outside the folder it reads
tar czf /tmp/bench_json.tgz --exclude gpu_check.log --exclude bench_json.tgz \
  -C benchmarks out && mv /tmp/bench_json.tgz "$OUTDIR/bench_json.tgz"
echo "=== done $(date -u +%T)" | tee -a "$LOG"
