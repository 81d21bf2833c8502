#!/usr/bin/env bash
# Confirm a walk-flat target held during training, from its checkpoint: the policy alone on 128
# fresh envs of an unused seed (eval-curve -> the run's evals_checkpoints.jsonl), then that
# checkpoint exported (a copy of the run resumed to iteration K exports its policy.onnx and
# bundle) and evaluated in both simulators (sim2sim), with a video of the scripted commands
# (forward, turn, sideways, stop; the camera follows the robot).
# Usage: confirm.sh RUN_DIR K [OUT]   (OUT: default runs/walk_flat_confirmed)
set -euo pipefail
run=$1
k=$2
out=${3:-runs/walk_flat_confirmed}
name=$(basename "$run")_it$k
export OMP_NUM_THREADS=1
a2cf-mb eval-curve "$run" --num-envs 128 --seed 20000 --every-iterations "$k"
mkdir -p "$out"
rm -rf "${out:?}/$name"
mkdir -p "$out/$name/checkpoints"
for f in config.json git.json warmstart.json; do
  [ -f "$run/$f" ] && cp "$run/$f" "$out/$name/"
done
cp "$run/checkpoints/model_$k.pt" "$out/$name/checkpoints/last.pt"
a2cf-mb train --resume "$out/$name" --iterations "$k"
a2cf-mb eval "$out/$name" --num-envs 128 --seed 20000 --sim2sim
MUJOCO_GL=${MUJOCO_GL:-egl} a2cf-mb eval "$out/$name" --num-envs 4 --seed 20001 --scripted \
  --video "$out/$name/walk_scripted.mp4"
