#!/usr/bin/env bash
# Confirm a walk-flat target held during training, from its checkpoint: the policy alone on 128
# fresh envs of an unused seed (eval-curve -> the run's evals_checkpoints.jsonl), then that
# checkpoint exported (../export_checkpoint.sh) and evaluated in both simulators (sim2sim), with
# a video of the scripted commands (forward, turn, sideways, stop; the camera follows the robot).
# Usage: confirm.sh RUN_DIR K [OUT]   (OUT: default runs/walk_flat_confirmed)
set -euo pipefail
run=$1
k=$2
out=${3:-runs/walk_flat_confirmed}
export OMP_NUM_THREADS=1
a2cf-mb eval-curve "$run" --num-envs 128 --seed 20000 --every-iterations "$k"
exported=$(bash "$(dirname "$0")/../export_checkpoint.sh" "$run" "$k" "$out")
a2cf-mb eval "$exported" --num-envs 128 --seed 20000 --sim2sim
MUJOCO_GL=${MUJOCO_GL:-egl} a2cf-mb eval "$exported" --num-envs 4 --seed 20001 --scripted \
  --video "$exported/walk_scripted.mp4"
