#!/usr/bin/env bash
# One GPU visit's check of the MuJoCo Warp backend (issues 22, 35), on a BARE machine of the lent
# image: its python3 (3.12, CUDA torch, numpy, scipy, onnx, tensorboard), no index, no .venv.
# docs/gpu.md ("A GPU visit") gives the calls minute by minute.
#
#   .venv/bin/python docs/results/gpu/make_payload.py          # here, once: .gpu_payload/py3.12/
#   device call i (carry .gpu_payload/py3.12/call<i>):  bash docs/results/gpu/run_gpu_check.sh
#
# Every call runs this same command. It first stashes the part it carried in $A2CF_PAYLOAD_DIR
# (/tmp/a2cf_payload, which lives as long as the machine: 30 s warm after each call). Until every
# part is there it says which are missing and exits 0. With all parts it unpacks them, installs
# the wheels with pip --target (no second torch), and runs the stages in order, each under its
# time limit, each writing its rows to $OUT/results.jsonl as they are measured:
#   compile (Warp kernels once) | warp (env alone and end to end, 4096/8192 envs, CUDA events) |
#   parity (stand and backflip, 64 envs, 20 steps, vs MuJoCo C) | train (20 iterations, 4096
#   envs) | mujoco (MuJoCo C, 1024 envs)
# $OUT gets 8 files, flat: summary.txt results.jsonl gpu_usage.csv and one log per stage.
# DEVICE=cpu and the sizes below make the CPU dry run (tests/test_gpu_dry_run.py).
set -uo pipefail
cd "$(dirname "$0")/../../.."
REPO=$PWD
: "${OUT:?set OUT to the folder for the figures}"
mkdir -p "$OUT"
STORE=${A2CF_PAYLOAD_DIR:-/tmp/a2cf_payload}
DEVICE=${DEVICE:-cuda}                          # Warp's device (and the learner's: cuda:0 / cpu)
WARP_SIZES=${WARP_SIZES:-4096 8192}             # envs of the warp stage [-]
WARP_STEPS=${WARP_STEPS:-50}                    # timed env steps per size [-]
WARP_ITERATIONS=${WARP_ITERATIONS:-2}           # timed training iterations per size [-]
COMPILE_ENVS=${COMPILE_ENVS:-8}                 # envs of the compile stage [-]
PARITY_TASKS=${PARITY_TASKS:-stand backflip}    # dance needs Pinocchio, which is not carried
PARITY_ENVS=${PARITY_ENVS:-64}                  # worlds per parity task [-]
PARITY_STEPS=${PARITY_STEPS:-20}                # policy steps compared [-]
TRAIN_ENVS=${TRAIN_ENVS:-4096}                  # envs of the training stage [-]
TRAIN_ITERATIONS=${TRAIN_ITERATIONS:-20}        # training iterations [-]
MUJOCO_ENVS=${MUJOCO_ENVS:-1024}                # envs of the MuJoCo C stage [-]
MUJOCO_STEPS=${MUJOCO_STEPS:-10}                # timed steps per chunk (3 chunks) [-]
MUJOCO_THREADS=${MUJOCO_THREADS:-0}             # MuJoCo C threads, 0 = all cores [-]
LIMIT_COMPILE_S=${LIMIT_COMPILE_S:-120}         # each stage's time limit [s]
LIMIT_WARP_S=${LIMIT_WARP_S:-75}
LIMIT_PARITY_S=${LIMIT_PARITY_S:-40}
LIMIT_TRAIN_S=${LIMIT_TRAIN_S:-60}
LIMIT_MUJOCO_S=${LIMIT_MUJOCO_S:-30}
SUMMARY=$OUT/summary.txt
RESULTS=$OUT/results.jsonl
say() { echo "$*" | tee -a "$SUMMARY"; }

# 1. Stash the carried part. A warm machine may keep the ignored folders of earlier calls beside
#    this call's (the newest): every part of the newest's payload goes in; a store of another
#    payload is emptied first.
newest=$(ls -td .gpu_payload/*/call*/ 2>/dev/null | head -1)
if [ -n "$newest" ]; then
  id=$(cat "$newest/payload.id")
  if [ "$(cat "$STORE/payload.id" 2>/dev/null)" != "$id" ]; then
    rm -rf "$STORE" && mkdir -p "$STORE/parts"
    cp "$newest/payload.id" "$newest/parts.sha256" "$STORE/"
  fi
  for folder in .gpu_payload/*/call*/; do
    [ "$(cat "$folder/payload.id")" = "$id" ] || continue
    for part in "$folder"payload.tar.xz.*; do
      name=$(basename "$part")
      cmp -s "$part" "$STORE/parts/$name" || cp "$part" "$STORE/parts/$name"
    done
  done
  say "stashed $newest of payload $id in $STORE ($(du -sh "$STORE/parts" | cut -f1))"
fi
[ -f "$STORE/parts.sha256" ] || { say "no payload in $STORE and none carried (see docs/gpu.md)"; exit 2; }
missing=$(awk '{print $2}' "$STORE/parts.sha256" | while read -r p; do
  [ -f "$STORE/parts/$p" ] || echo "$p"; done)
if [ -n "$missing" ]; then
  say "waiting for: $(echo $missing) (next call carries the next part; machine warm for 30 s)"
  exit 0
fi

# 2. Unpack and install once per machine (a rerun on the warm machine starts at the stages).
if [ ! -f "$STORE/installed" ]; then
  start=$SECONDS
  (cd "$STORE/parts" && sha256sum -c --quiet ../parts.sha256) || { say "a part is corrupt"; exit 3; }
  cat "$STORE"/parts/payload.tar.xz.* | python3 -c "
import sys, tarfile
tarfile.open(fileobj=sys.stdin.buffer, mode='r|xz').extractall(sys.argv[1], filter='data')
" "$STORE/unpacked" || { say "unpacking failed"; exit 3; }
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target "$STORE/site" "$STORE"/unpacked/wheels/*.whl 2>&1 | tee -a "$SUMMARY"
  [ "${PIPESTATUS[0]}" -eq 0 ] || { say "pip install failed"; exit 3; }
  touch "$STORE/installed"
  say "unpacked and installed in $((SECONDS - start)) s"
fi
export PYTHONPATH=$REPO:$STORE/site
export A2CF_G1_DESCRIPTION_DIR=$STORE/unpacked/g1_description
export WARP_CACHE_PATH=${WARP_CACHE_PATH:-$STORE/warp_cache}  # kept while the machine is warm
export PYTHONUNBUFFERED=1
export GIT_PYTHON_REFRESH=quiet                  # rsl-rl imports GitPython; git may be absent
[ "$DEVICE" = cpu ] && export CUDA_VISIBLE_DEVICES=""
LEARNER=$([ "$DEVICE" = cpu ] && echo cpu || echo cuda:0)

{
  date -u
  git rev-parse HEAD 2>/dev/null || echo "no git here"
  [ "$DEVICE" = cpu ] || nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
  python3 -c "
import sys, torch, mujoco, warp, mujoco_warp, rsl_rl
print('python', sys.version.split()[0], 'torch', torch.__version__, 'cuda', torch.cuda.is_available(),
      'mujoco', mujoco.__version__, 'warp', warp.__version__, 'mujoco_warp', mujoco_warp.__version__)
print('torch from', torch.__file__)"
} 2>&1 | tee -a "$SUMMARY"

status=0
stage() {  # stage NAME LIMIT_S COMMAND...: log to $OUT/NAME.log, record the exit code
  local name=$1 limit=$2
  shift 2
  say "== $name (limit ${limit}s)"
  local start=$SECONDS
  timeout -k 5 "$limit" "$@" >"$OUT/$name.log" 2>&1
  local rc=$?
  local note=""
  [ "$rc" -eq 124 ] || [ "$rc" -eq 137 ] && note=" (cut off by its limit; its rows so far are kept)"
  say "   exit $rc after $((SECONDS - start)) s$note"
  [ "$rc" -eq 0 ] || status=1
}

if [ "$DEVICE" != cpu ]; then
  nvidia-smi --query-gpu=timestamp,memory.used,utilization.gpu --format=csv -l 2 \
    >"$OUT/gpu_usage.csv" 2>/dev/null &
  SMI=$!
fi
S=docs/results/gpu/stages.py
# shellcheck disable=SC2086  # WARP_SIZES and PARITY_TASKS are lists
stage compile "$LIMIT_COMPILE_S" python3 -u $S compile --device "$DEVICE" \
  --num-envs "$COMPILE_ENVS" --parity-tasks $PARITY_TASKS --rows "$RESULTS"
stage warp "$LIMIT_WARP_S" python3 -u $S warp --device "$DEVICE" --sizes $WARP_SIZES \
  --steps "$WARP_STEPS" --iterations "$WARP_ITERATIONS" --run-root "$STORE/runs" --rows "$RESULTS"
stage parity "$LIMIT_PARITY_S" python3 -u docs/results/gpu/parity.py --device "$DEVICE" \
  --tasks $PARITY_TASKS --num-envs "$PARITY_ENVS" --steps "$PARITY_STEPS" --rows "$RESULTS"
rm -rf "$STORE/runs/check"
stage train "$LIMIT_TRAIN_S" python3 -u -m a2cf_mb train --task walk-flat --env-backend warp \
  --env-device "$DEVICE" --num-envs "$TRAIN_ENVS" --device "$LEARNER" \
  --iterations "$TRAIN_ITERATIONS" --save-interval "$TRAIN_ITERATIONS" --eval-interval 0 \
  --no-export-onnx --out "$STORE/runs" --run-name check
python3 $S train-rows --run "$STORE/runs/check" --rows "$RESULTS" >/dev/null 2>>"$OUT/train.log"
stage mujoco "$LIMIT_MUJOCO_S" python3 -u $S mujoco --num-envs "$MUJOCO_ENVS" \
  --steps "$MUJOCO_STEPS" --num-threads "$MUJOCO_THREADS" --rows "$RESULTS"
[ -n "${SMI:-}" ] && kill "$SMI" 2>/dev/null

{
  echo "== figures ($(wc -l <"$RESULTS" 2>/dev/null || echo 0) rows in results.jsonl)"
  python3 - "$RESULTS" <<'EOF'
import json, sys
rows = [json.loads(x) for x in open(sys.argv[1])] if __import__("os").path.exists(sys.argv[1]) else []
for r in rows:
    s = r["stage"]
    if s == "compile":
        print(f"compile {r['task']}: build {r['build_s']:.1f} s, first step {r['first_step']['wall_s']:.1f} s")
    elif s == "warp":
        rate = r.get("cuda_event_env_steps_per_s", r["wall_env_steps_per_s"])
        print(f"warp {r['what']} N={r['num_envs']}: {rate:.0f} env steps/s")
    elif s == "parity" and "max" in r:
        print("parity max:", r["max"], "wrench acc diff:", r["wrench_acc_diff"])
    elif s == "mujoco":
        print(f"mujoco N={r['num_envs']} ({r['threads']} threads): {r['env_steps_per_s']:.0f} env steps/s")
its = [r for r in rows if r["stage"] == "train" and "iteration" in r]
if its:
    print(f"train: {len(its)} iterations, last {its[-1]}")
EOF
} 2>&1 | tee -a "$SUMMARY"
say "done: exit $status"
exit "$status"
