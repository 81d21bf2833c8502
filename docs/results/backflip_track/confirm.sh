#!/usr/bin/env bash
# Confirm a backflip checkpoint alone: the policy on N fresh envs of an unused seed, from standing
# (eval-curve -> the run's evals_checkpoints.jsonl: flips landed, turn, phase reached), then that
# checkpoint exported (a copy of the run resumed to iteration K exports its policy.onnx and
# bundle) and evaluated in both simulators (sim2sim: training physics against the second
# simulator), with a video of env 0 alone (tracking camera, the reference's ghost beside it).
# Usage: confirm.sh RUN_DIR K [OUT] [N]   (OUT: default runs/backflip_track_confirmed, N: 128)
set -euo pipefail
run=$1
k=$2
out=${3:-runs/backflip_track_confirmed}
n=${4:-128}
name=$(basename "$run")_it$k
export OMP_NUM_THREADS=1
a2cf-mb eval-curve "$run" --num-envs "$n" --seed 20000 --every-iterations "$k"
mkdir -p "$out"
rm -rf "${out:?}/$name"
mkdir -p "$out/$name/checkpoints"
for f in config.json git.json warmstart.json; do
  [ -f "$run/$f" ] && cp "$run/$f" "$out/$name/"
done
cp "$run/checkpoints/model_$k.pt" "$out/$name/checkpoints/last.pt"
a2cf-mb train --resume "$out/$name" --iterations "$k"
a2cf-mb eval "$out/$name" --num-envs "$n" --seed 20000 --sim2sim | tee "$out/$name/eval_sim2sim.txt"
MUJOCO_GL=${MUJOCO_GL:-egl} a2cf-mb eval "$out/$name" --num-envs 4 --seed 20001 \
  --video-speed 0.25 --video "$out/$name/flip_alone.mp4"
