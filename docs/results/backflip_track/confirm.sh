#!/usr/bin/env bash
# Confirm a backflip checkpoint alone: the policy on N fresh envs of an unused seed, from standing
# (eval-curve -> the run's evals_checkpoints.jsonl: flips landed, turn, phase reached), then that
# checkpoint exported (../export_checkpoint.sh) and evaluated in both simulators (sim2sim with the
# flip judge: flips landed in the training physics and in the second simulator), with a
# slow-motion video of env 0 alone (tracking camera, the reference's ghost beside it).
# Usage: confirm.sh RUN_DIR K [OUT] [N]   (OUT: default runs/backflip_track_confirmed, N: 128)
set -euo pipefail
run=$1
k=$2
out=${3:-runs/backflip_track_confirmed}
n=${4:-128}
export OMP_NUM_THREADS=1
a2cf-mb eval-curve "$run" --num-envs "$n" --seed 20000 --every-iterations "$k"
exported=$(bash "$(dirname "$0")/../export_checkpoint.sh" "$run" "$k" "$out")
a2cf-mb eval "$exported" --num-envs "$n" --seed 20000 --sim2sim | tee "$exported/eval_sim2sim.txt"
MUJOCO_GL=${MUJOCO_GL:-egl} a2cf-mb eval "$exported" --num-envs 4 --seed 20001 \
  --video-speed 0.25 --video "$exported/flip_alone.mp4"
