#!/usr/bin/env bash
# Dance: baseline / a2cf / a2cf + warm start (paper rule, quantile rule, + motion warm start),
# same seed, envs and budget, all five in parallel on a 2-core CPU; then each motion policy
# evaluated alone (assistance off) on 64 fresh envs, and `a2cf-mb compare`.
# Usage: run.sh [ITERATIONS]  (default 300; rerunning with more resumes each run exactly).
set -euo pipefail
cd "$(dirname "$0")/../../.."
ITERS=${1:-300}
OUT=runs/dance_warmstart
ORACLE=$OUT/oracle
export OMP_NUM_THREADS=1
[ -f "$ORACLE/manifest.json" ] || a2cf-mb solve-dance --out "$ORACLE" > "$OUT/oracle.log" 2>&1
COMMON="--task dance --env-num-envs 64 --env-num-threads 1 --env-seed 0 --num-steps-per-env 24 --save-interval 50 --out $OUT"
declare -A SPECS=(
  [baseline]="--mode baseline"
  [a2cf]="--mode a2cf"
  [a2cf_warm]="--mode a2cf --warmstart $ORACLE"
  [a2cf_warm_q]="--mode a2cf --warmstart $ORACLE --curriculum-force-measure quantile"
  [a2cf_warm_motion_q]="--mode a2cf --warmstart $ORACLE --warmstart-motion --curriculum-force-measure quantile"
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
a2cf-mb compare $OUT/baseline $OUT/a2cf $OUT/a2cf_warm $OUT/a2cf_warm_q $OUT/a2cf_warm_motion_q \
  --levels 0.5 0.8 1.0 --out $OUT
