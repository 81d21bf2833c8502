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
#   envs) | mujoco (MuJoCo C, 1024 envs) | backflip (the backflip by tracking the carried
#   solve-backflip artifact, docs/results/backflip_track: 4096 envs, evaluated alone every 20
#   iterations, for the seconds the call has left)
# $OUT gets 6 files, flat: summary.txt results.jsonl gpu_usage.csv checks.log (the first five
# stages' output, one after the other) backflip.log backflip_run.tar (the run folder's config,
# metrics, evaluations and checkpoints/last.pt: unpack into runs/backflip_track/ to continue it).
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
BACKFLIP_MODE=${BACKFLIP_MODE:-baseline}        # baseline | a2cf | coach (backflip_track/run.sh's)
BACKFLIP_ENVS=${BACKFLIP_ENVS:-4096}            # envs of the backflip stage [-]
BACKFLIP_ITERATIONS=${BACKFLIP_ITERATIONS:-305} # the run's total: 30 M env steps at 4096 x 24 [-]
BACKFLIP_EVAL_INTERVAL=${BACKFLIP_EVAL_INTERVAL:-20}  # iterations between evaluations alone [-]
BACKFLIP_EVAL_ENVS=${BACKFLIP_EVAL_ENVS:-256}   # fresh envs from standing per evaluation [-]
BACKFLIP_SEED=${BACKFLIP_SEED:-0}
# 1: the oracle's feed-forward in the PD law (--task-action-feedforward; on the CPU it took the
# turn alone from 1 rad at 12 M env steps to 4-4.6 rad at 1-2 M: backflip_track/README.md)
BACKFLIP_FEEDFORWARD=${BACKFLIP_FEEDFORWARD:-1}
# a2cf's anneal: run.sh's 3000 iterations at 128 envs (9.2 M env steps) at this stage's envs
BACKFLIP_ANNEAL=${BACKFLIP_ANNEAL:-$(( (3000 * 128 + BACKFLIP_ENVS / 2) / BACKFLIP_ENVS ))}
ff_name=""; [ "$BACKFLIP_FEEDFORWARD" = 1 ] && ff_name="ff_"
BACKFLIP_RUN=${BACKFLIP_RUN:-flip_gpu_${ff_name}${BACKFLIP_MODE}_s${BACKFLIP_SEED}}
# The backflip stage runs until the call's end less a margin (packing the run, the figures):
# the device tool stops a call after 600 s. A number here fixes its limit instead.
CALL_LIMIT_S=${CALL_LIMIT_S:-600}               # the device tool's limit on one call [s]
CALL_MARGIN_S=${CALL_MARGIN_S:-60}              # left at the end of the call [s]
LIMIT_BACKFLIP_S=${LIMIT_BACKFLIP_S:-}          # empty: CALL_LIMIT_S - CALL_MARGIN_S - elapsed [s]
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
  if [ -d "$newest/backflip_oracle" ]; then  # the track task's reference (make_payload.py)
    rm -rf "$STORE/backflip_oracle" && cp -r "$newest/backflip_oracle" "$STORE/backflip_oracle"
  fi
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
stage() {  # stage NAME LOG LIMIT_S COMMAND...: append to $OUT/LOG, record the exit code
  local name=$1 log=$OUT/$2 limit=$3
  shift 3
  say "== $name (limit ${limit}s)"
  echo "===== $name (limit ${limit}s) $(date -u +%T)" >>"$log"
  local start=$SECONDS
  timeout -k 5 "$limit" "$@" >>"$log" 2>&1
  local rc=$?
  local note=""
  [ "$rc" -eq 124 ] || [ "$rc" -eq 137 ] && note=" (cut off by its limit; its rows so far are kept)"
  say "   exit $rc after $((SECONDS - start)) s$note"
  # the backflip trains until its limit: being cut off is its normal end (last.pt is kept)
  [ "$rc" -eq 0 ] || { [ "$name" = backflip ] && [ -n "$note" ]; } || status=1
}

if [ "$DEVICE" != cpu ]; then
  nvidia-smi --query-gpu=timestamp,memory.used,utilization.gpu --format=csv -l 2 \
    >"$OUT/gpu_usage.csv" 2>/dev/null &
  SMI=$!
fi
S=docs/results/gpu/stages.py
# shellcheck disable=SC2086  # WARP_SIZES and PARITY_TASKS are lists
stage compile checks.log "$LIMIT_COMPILE_S" python3 -u $S compile --device "$DEVICE" \
  --num-envs "$COMPILE_ENVS" --parity-tasks $PARITY_TASKS --rows "$RESULTS"
stage warp checks.log "$LIMIT_WARP_S" python3 -u $S warp --device "$DEVICE" --sizes $WARP_SIZES \
  --steps "$WARP_STEPS" --iterations "$WARP_ITERATIONS" --run-root "$STORE/runs" --rows "$RESULTS"
stage parity checks.log "$LIMIT_PARITY_S" python3 -u docs/results/gpu/parity.py --device "$DEVICE" \
  --tasks $PARITY_TASKS --num-envs "$PARITY_ENVS" --steps "$PARITY_STEPS" --rows "$RESULTS"
rm -rf "$STORE/runs/check"
stage train checks.log "$LIMIT_TRAIN_S" python3 -u -m a2cf_mb train --task walk-flat --env-backend warp \
  --env-device "$DEVICE" --num-envs "$TRAIN_ENVS" --device "$LEARNER" \
  --iterations "$TRAIN_ITERATIONS" --save-interval "$TRAIN_ITERATIONS" --eval-interval 0 \
  --no-export-onnx --out "$STORE/runs" --run-name check
python3 $S train-rows --run "$STORE/runs/check" --rows "$RESULTS" >/dev/null 2>>"$OUT/checks.log"
stage mujoco checks.log "$LIMIT_MUJOCO_S" python3 -u $S mujoco --num-envs "$MUJOCO_ENVS" \
  --steps "$MUJOCO_STEPS" --num-threads "$MUJOCO_THREADS" --rows "$RESULTS"

# The backflip by tracking (docs/results/backflip_track): the carried artifact is the reference,
# at the path run.sh uses, so the run's config names it as a run here would. A run folder of that
# name already in the checkout (carried from an earlier visit, or left by a rerun on this warm
# machine) is continued with --resume.
FLIP=runs/backflip_track
RUN=$FLIP/$BACKFLIP_RUN
elapsed=$SECONDS
limit=${LIMIT_BACKFLIP_S:-$((CALL_LIMIT_S - CALL_MARGIN_S - elapsed))}
flip_args=()
case "$BACKFLIP_MODE" in
  baseline) ;;
  a2cf) flip_args=(--warmstart "$FLIP/oracle" --curriculum-anneal-iterations "$BACKFLIP_ANNEAL") ;;
  coach) flip_args=(--coach-source "$FLIP/oracle") ;;
  *) say "backflip: unknown BACKFLIP_MODE '$BACKFLIP_MODE' (baseline, a2cf or coach)"; limit=0 ;;
esac
if [ "$BACKFLIP_MODE" != baseline ] && ! python3 -c "import pinocchio" 2>/dev/null; then
  say "backflip: mode $BACKFLIP_MODE needs Pinocchio (the artifact's coach), not on this machine"
  limit=0
fi
if [ ! -d "$STORE/backflip_oracle" ]; then
  say "backflip: no solve-backflip artifact carried (make_payload.py --reference); stage skipped"
elif [ "$limit" -lt 30 ]; then
  say "backflip: ${limit}s left after ${elapsed}s; stage skipped"
else
  mkdir -p "$FLIP"
  [ -d "$FLIP/oracle" ] || cp -r "$STORE/backflip_oracle" "$FLIP/oracle"
  if [ -f "$RUN/config.json" ]; then
    flip_run=(--resume "$RUN")
  else
    flip_run=(--task track --reference "$FLIP/oracle" --task-actions-around-reference
              --env-backend warp --env-device "$DEVICE" --num-envs "$BACKFLIP_ENVS"
              --device "$LEARNER" --mode "$BACKFLIP_MODE" --seed "$BACKFLIP_SEED"
              --save-interval "$BACKFLIP_EVAL_INTERVAL" --eval-interval "$BACKFLIP_EVAL_INTERVAL"
              --eval-num-envs "$BACKFLIP_EVAL_ENVS" --no-export-onnx --out "$FLIP"
              --run-name "$BACKFLIP_RUN" "${flip_args[@]}")
    [ "$BACKFLIP_FEEDFORWARD" = 1 ] && flip_run+=(--task-action-feedforward)
  fi
  stage backflip backflip.log "$limit" python3 -u -m a2cf_mb train "${flip_run[@]}" \
    --iterations "$BACKFLIP_ITERATIONS"
  python3 $S train-rows --row-stage backflip --run "$RUN" --rows "$RESULTS" >/dev/null \
    2>>"$OUT/backflip.log"
  # What continues the run: everything but the kept model_<it>.pt and rsl-rl's code diff
  tar -cf "$OUT/backflip_run.tar" -C "$FLIP" --exclude "$BACKFLIP_RUN/checkpoints/model_*" \
    --exclude "$BACKFLIP_RUN/git" --exclude "$BACKFLIP_RUN/run.lock" "$BACKFLIP_RUN" \
    && say "   $BACKFLIP_RUN packed: backflip_run.tar ($(du -h "$OUT/backflip_run.tar" | cut -f1))"
fi
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
flips = [r for r in rows if r["stage"] == "backflip" and "iteration" in r]
if flips:
    print(f"backflip: {len(flips)} iterations, last {flips[-1]}")
for r in rows:
    if r["stage"] == "backflip_eval":
        print(f"backflip eval it {r['iteration']}: flips landed {r.get('flips_landed')}, "
              f"turn mean {r.get('turn_rad_mean')} rad, survival {r.get('survival_fraction')}")
EOF
} 2>&1 | tee -a "$SUMMARY"
say "done: exit $status"
exit "$status"
