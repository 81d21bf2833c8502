#!/usr/bin/env bash
# Walk: baseline / a2cf / a2cf + warm start (eta0 from the walk oracle, posture coach distilled,
# quantile force measure), same seed, envs and budget, in parallel on a 2-core CPU; then each
# motion policy evaluated alone (assistance off) on 64 fresh envs, and `a2cf-mb compare`.
# Usage: run.sh [ITERATIONS]  (default 600; rerunning with more resumes each run exactly).
set -euo pipefail
cd "$(dirname "$0")/../../.."
ITERS=${1:-600}
OUT=runs/walk_warmstart
ORACLE=$OUT/oracle
export OMP_NUM_THREADS=1
mkdir -p "$OUT"
[ -f "$ORACLE/manifest.json" ] || a2cf-mb solve-walk --out "$ORACLE" > "$OUT/oracle.log" 2>&1
COMMON="--task walk --env-num-envs 64 --env-num-threads 1 --env-seed 0 --num-steps-per-env 24 --save-interval 100 --out $OUT"
declare -A SPECS=(
  [baseline]="--mode baseline"
  [a2cf]="--mode a2cf"
  [a2cf_warm_q]="--mode a2cf --warmstart $ORACLE --curriculum-force-measure quantile"
)
for name in "${!SPECS[@]}"; do
  (
    if [ -f "$OUT/$name/config.json" ]; then
      a2cf-mb train --resume "$OUT/$name" --iterations "$ITERS"
    else
      a2cf-mb train --run-name "$name" ${SPECS[$name]} --iterations "$ITERS" $COMMON
    fi > "$OUT/$name.log" 2>&1
    a2cf-mb eval "$OUT/$name" --num-envs 64 --seed 1 > "$OUT/$name-eval.log" 2>&1
    cp "$OUT/$name/eval.json" "$OUT/$name/eval_it$ITERS.json"
  ) &
done
wait
a2cf-mb compare $OUT/baseline $OUT/a2cf $OUT/a2cf_warm_q --out $OUT
