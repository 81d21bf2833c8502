#!/usr/bin/env bash
# Walk: baseline / a2cf / a2cf + warm start (eta0 from the walk oracle, posture coach distilled,
# quantile force measure), in parallel on a 2-core CPU, then assist-off evaluations and compare.
# Usage: run.sh [ITERATIONS]  (measured: run.sh 400).
cd "$(dirname "$0")/../../.."
TASK=walk OUT=runs/walk_warmstart ITERS=${1:-400} SAVE_INTERVAL=100 SOLVE=solve-walk
declare -A SPECS=(
  [baseline]="--mode baseline"
  [a2cf]="--mode a2cf"
  [a2cf_warm_q]='--mode a2cf --warmstart $ORACLE --curriculum-force-measure quantile'
)
RUN_ORDER=(baseline a2cf a2cf_warm_q)
source docs/results/run_comparison.sh
