#!/usr/bin/env bash
# Dance: baseline / a2cf / a2cf + warm start (paper rule, quantile rule, + motion warm start), all
# five in parallel on a 2-core CPU, then assist-off evaluations and `a2cf-mb compare`.
# Usage: run.sh [ITERATIONS]  (measured: run.sh 300, then run.sh 800, which resumes each run).
cd "$(dirname "$0")/../../.."
TASK=dance OUT=runs/dance_warmstart ITERS=${1:-300} SAVE_INTERVAL=50 SOLVE=solve-dance
COMPARE_FLAGS="--levels 0.5 0.8 1.0"
declare -A SPECS=(
  [baseline]="--mode baseline"
  [a2cf]="--mode a2cf"
  [a2cf_warm]='--mode a2cf --warmstart $ORACLE'
  [a2cf_warm_q]='--mode a2cf --warmstart $ORACLE --curriculum-force-measure quantile'
  [a2cf_warm_motion_q]='--mode a2cf --warmstart $ORACLE --warmstart-motion --curriculum-force-measure quantile'
)
RUN_ORDER=(baseline a2cf a2cf_warm a2cf_warm_q a2cf_warm_motion_q)
source docs/results/run_comparison.sh
