#!/usr/bin/env bash
# One prepared check of the MuJoCo Warp backend on a CUDA GPU (issue 22). Writes every figure
# under $OUT; prints a summary at the end. Nothing here has been run on a GPU yet: the figures are
# to be measured.
#
#   OUT=/path/to/out bash docs/results/gpu/run_gpu_check.sh
#
# Needs: the repository's virtual environment (.venv) with the gpu extra
#   (.venv/bin/pip install -e ".[gpu]"), or WHEELS=/folder/of/wheels for an offline install
#   (bash docs/results/gpu/make_wheels.sh WHEELS on a machine with an index: 873 MB, docs/gpu.md).
# Budget: about 9 minutes wall clock (stage limits below: 120 + 90 + 90 + 240 s, plus start-up).
set -uo pipefail
cd "$(dirname "$0")/../../.."
: "${OUT:?set OUT to the folder for the figures}"
mkdir -p "$OUT"
PY=.venv/bin/python
if [ -n "${WHEELS:-}" ]; then
  .venv/bin/pip install -q --no-index --find-links "$WHEELS" -e ".[gpu]" 2>&1 | tail -3
fi
# Warp compiles its kernels for the GPU on first use (minutes); keep the cache with the run.
export WARP_CACHE_PATH="${WARP_CACHE_PATH:-$OUT/warp_cache}"
status=0
run() {  # run NAME LIMIT_S COMMAND...: log to $OUT/NAME.log, record the exit code
  local name=$1 limit=$2
  shift 2
  echo "== $name (limit ${limit}s): $*" | tee -a "$OUT/summary.txt"
  local start=$SECONDS
  timeout "$limit" "$@" >"$OUT/$name.log" 2>&1
  local rc=$?
  echo "   exit $rc after $((SECONDS - start)) s" | tee -a "$OUT/summary.txt"
  [ "$rc" -eq 0 ] || status=1
}

{ nvidia-smi; $PY -c "import mujoco_warp, warp, mujoco, torch; print('mujoco', mujoco.__version__, 'mujoco_warp', mujoco_warp.__version__, 'warp', warp.__version__, 'torch', torch.__version__)"; } >"$OUT/machine.txt" 2>&1
git rev-parse HEAD >>"$OUT/machine.txt" 2>&1

# 1. Parity on the GPU against MuJoCo C (same states and actions; the CUDA graph replays from the
#    second step on). The slow Warp tests on cuda are left to a longer lease:
#    env A2CF_WARP_DEVICE=cuda .venv/bin/pytest -q -m slow tests/test_warp_physics.py
run parity_cuda 120 $PY docs/results/gpu/parity.py --device cuda --num-envs 64 --steps 20 \
  --out "$OUT/parity_cuda.json"

# 2. Env throughput (policy steps of all envs per second): stand on MuJoCo C and Warp at 1024
#    worlds in the same run, Warp alone at 4096 and 8192; walk-flat on Warp at 4096 and 8192.
run bench_env_stand 90 .venv/bin/a2cf-mb bench env --task stand --backends mujoco warp \
  --device cuda --num-envs 1024 4096 8192 --link-collisions on --num-steps 30 --repeats 1 \
  --num-threads 16 --output "$OUT/bench_env_stand.json"
run bench_env_walk_flat 90 .venv/bin/a2cf-mb bench env --task walk-flat --backends warp \
  --device cuda --num-envs 4096 8192 --link-collisions on --num-steps 30 --repeats 1 \
  --output "$OUT/bench_env_walk_flat.json"

# 3. walk-flat trained for the remaining minutes at 4096 envs (physics and learner on the GPU):
#    its metrics.json gives the end-to-end env steps/s and the iteration time per iteration,
#    gpu_usage.csv the GPU memory, evals.jsonl the policy alone (assistance off, 256 fresh envs)
#    every 20 iterations.
nvidia-smi --query-gpu=timestamp,memory.used,utilization.gpu --format=csv -l 5 \
  >"$OUT/gpu_usage.csv" 2>/dev/null &
SMI=$!
run train_walk_flat 240 .venv/bin/a2cf-mb train --task walk-flat --env-backend warp \
  --env-device cuda --num-envs 4096 --device cuda:0 --iterations 60 --save-interval 20 \
  --eval-interval 20 --eval-num-envs 256 --out "$OUT/runs" --run-name walk_flat_warp_4096
kill "$SMI" 2>/dev/null

{
  echo "== figures"
  $PY - "$OUT" <<'EOF'
import json, pathlib, sys
out = pathlib.Path(sys.argv[1])
for name in ("parity_cuda.json", "bench_env_stand.json", "bench_env_walk_flat.json"):
    p = out / name
    if not p.is_file():
        print(name, "missing")
        continue
    d = json.loads(p.read_text())
    if "tasks" in d:
        print("parity max errors:", {t: r["max"] for t, r in d["tasks"].items()},
              "wrench acc diff:", d["wrench"]["max_abs_diff"])
    else:
        for key, r in d["sizes"].items():
            print(key, {k: round(v, 3) if isinstance(v, float) else v for k, v in r.items()})
m = out / "runs" / "walk_flat_warp_4096" / "metrics.json"
if m.is_file():
    its = json.loads(m.read_text())["iterations"]
    print("train: iterations", len(its), "last", {k: its[-1][k] for k in list(its[-1])[:8]})
    evals = out / "runs" / "walk_flat_warp_4096" / "evals.jsonl"
    for line in evals.read_text().splitlines() if evals.is_file() else []:
        print("alone:", json.loads(line))
    mem = out / "gpu_usage.csv"
    if mem.is_file():
        used = [int(r.split(",")[1].split()[0]) for r in mem.read_text().splitlines()[1:] if "MiB" in r]
        print("GPU memory used, max:", max(used, default=0), "MiB")
else:
    print("train: no metrics.json (see train_walk_flat.log)")
EOF
} 2>&1 | tee -a "$OUT/summary.txt"
exit "$status"
