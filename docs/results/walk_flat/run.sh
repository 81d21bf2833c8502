#!/usr/bin/env bash
# "Walking learned on this CPU" (issue 33): walk-flat (the default recipe: unitree_rl_gym's G1
# terms, gait clock, command curriculum, pushes), 128 envs x 24 steps (stand and dance learned more
# per env step at 128 than at 512), 9766 iterations = 30.0 M env steps, evaluated alone every 100
# iterations (32 fresh envs, seed 10000). One physics and one torch thread per run.
# Usage: bash docs/results/walk_flat/run.sh [baseline|a2cf|no-pi] [NAME_SUFFIX EXTRA_TRAIN_FLAGS...]
#   (SEED=0, OUT=runs/walk_flat), e.g. the warm-started A2CF run:
#   a2cf-mb solve-walk --no-video --out runs/oracle_walk
#   bash docs/results/walk_flat/run.sh a2cf _warm --warmstart runs/oracle_walk
# Continue a run cut off by the end of a session: a2cf-mb train --resume "$OUT/<run>"
# The study's recipe is walk-flat's of Dec 5: yaw-rate tracking weighed 0.5 (the default is 2.0
# since Dec 7), pinned below; a --task-reward-weight of your own replaces the pin (add
# track_ang_vel_z=0.5 to it to keep the study's).
set -euo pipefail
OUT=${OUT:-runs/walk_flat}
seed=${SEED:-0}
mode=${1:-baseline}
suffix=${2:-}
shift $(( $# > 2 ? 2 : $# ))
export OMP_NUM_THREADS=1
a2cf-mb train --task walk-flat --mode "$mode" --seed "$seed" --num-envs 128 --env-num-threads 1 \
  --save-interval 100 --eval-interval 100 --iterations 9766 --out "$OUT" \
  --run-name "walkflat_${mode}${suffix}_128_s$seed" --task-reward-weight track_ang_vel_z=0.5 "$@"
