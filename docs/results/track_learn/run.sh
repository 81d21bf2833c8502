#!/usr/bin/env bash
# "Motion tracking that tracks" (issue 31): the track recipe (rl/tasks/track) on the built-in dance
# (`--task dance` = `track` on "builtin", 19 s, 0.28 rad mean |q - q_stand|), baseline (no help),
# 128 envs x 24 steps, 3256 iterations = 10.0 M env steps, evaluated alone every 60 iterations
# (32 fresh envs, seed 10000, from the dance's first frame). One physics and one torch thread per
# run; the three seeds ran at once on the 2-core machine.
# Usage: bash docs/results/track_learn/run.sh [baseline]   (OUT=runs/track_learn by default)
# Continue a run cut off by the end of a session: a2cf-mb train --resume "$OUT/<run>"
set -euo pipefail
OUT=${OUT:-runs/track_learn}
export OMP_NUM_THREADS=1
common=(--num-envs 128 --env-num-threads 1 --save-interval 60 --eval-interval 60 --iterations 3256 --out "$OUT")
case "${1:-baseline}" in
baseline)
  for seed in 0 1 2; do
    a2cf-mb train --task dance --mode baseline --seed "$seed" "${common[@]}" --run-name "dance_baseline_s$seed" &
  done
  wait ;;
*) echo "unknown case $1" >&2; exit 2 ;;
esac
