#!/usr/bin/env bash
# "A walk that goes where it is told" (issue 53): walk-flat with the policy on its own senses (no
# pelvis velocity in the actor), 40 % pure command draws, and the judge per command kind (every
# kind within half of a robot standing still's error, survival >= 90 % under pushes). 128 envs x
# 24 steps, 9766 iterations = 30.0 M env steps, evaluated alone every 100 iterations (32 fresh
# envs, seed 10000). One physics and one torch thread per run.
# Usage: SEED=0 bash docs/results/walk_kinds/run.sh baseline|a2cf [EXTRA_TRAIN_FLAGS...]
#   A2CF is warm-started from the walk oracle (made once: a2cf-mb solve-walk --no-video --out
#   runs/oracle_walk). Continue a run cut off by the end of a session:
#   a2cf-mb train --resume "$OUT/<run>"
set -euo pipefail
OUT=${OUT:-runs/walk_kinds}
seed=${SEED:-0}
mode=${1:-baseline}
shift $(( $# > 0 ? 1 : 0 ))
warm=()
suffix=""
if [ "$mode" = "a2cf" ]; then
  warm=(--warmstart "${ORACLE:-runs/oracle_walk}")
  suffix="_warm"
fi
export OMP_NUM_THREADS=1
exec a2cf-mb train --task walk-flat --mode "$mode" --seed "$seed" --num-envs 128 \
  --env-num-threads 1 --save-interval 100 --eval-interval 100 --iterations 9766 --out "$OUT" \
  --run-name "walkkinds_${mode}${suffix}_128_s$seed" "${warm[@]}" "$@"
