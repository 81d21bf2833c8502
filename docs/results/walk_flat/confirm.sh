#!/usr/bin/env bash
# Confirm a walk-flat target held during training, from its checkpoint: the policy alone on 128
# fresh envs of an unused seed (eval-curve -> the run's evals_checkpoints.jsonl), then that
# checkpoint exported (../export_checkpoint.sh) and evaluated in both simulators (sim2sim), with
# a video of the scripted commands (forward, turn, sideways, stop; the camera follows the robot).
# Usage: confirm.sh RUN_DIR K [OUT]   (OUT: default runs/walk_flat_confirmed); exit code 1 where the
# 128 envs miss the target (the export and sim2sim are then skipped unless CONFIRM_ANYWAY=1)
set -euo pipefail
run=$1
k=$2
out=${3:-runs/walk_flat_confirmed}
export OMP_NUM_THREADS=1
a2cf-mb eval-curve "$run" --num-envs 128 --seed 20000 --every-iterations "$k"
# not confirmed on 128 envs: the export, sim2sim and video would judge nothing (CONFIRM_ANYWAY=1 runs them)
if ! python - "$run/evals_checkpoints.jsonl" "$k" <<'PY'
import json, sys
rows = [json.loads(r) for r in open(sys.argv[1]) if r.strip()]
row = [r for r in rows if r["iteration"] == int(sys.argv[2])][-1]
sys.exit(0 if row["target_reached"] else 1)
PY
then
  echo "confirm.sh: $run iteration $k misses the target on 128 fresh envs; not exported" >&2
  [ "${CONFIRM_ANYWAY:-0}" = 1 ] || exit 1
fi
exported=$(bash "$(dirname "$0")/../export_checkpoint.sh" "$run" "$k" "$out")
a2cf-mb eval "$exported" --num-envs 128 --seed 20000 --sim2sim
MUJOCO_GL=${MUJOCO_GL:-egl} a2cf-mb eval "$exported" --num-envs 4 --seed 20001 --scripted \
  --video "$exported/walk_scripted.mp4"
