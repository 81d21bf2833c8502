#!/usr/bin/env bash
# Shared body of the comparison scripts (sourced by docs/results/*_warmstart/run.sh): the caller
# sets TASK, OUT, ITERS, SAVE_INTERVAL, SOLVE (the oracle command) and the associative array SPECS
# (run name -> mode flags; "$ORACLE" stands for the oracle folder). Every run trains in parallel
# with the same seed, envs and budget (or resumes exactly to ITERS), then its motion policy is
# evaluated alone (assistance off) on 64 fresh envs; eval.json is kept as eval_it<ITERS>.json.
set -euo pipefail
export OMP_NUM_THREADS=1
ORACLE=$OUT/oracle
mkdir -p "$OUT"
[ -f "$ORACLE/manifest.json" ] || a2cf-mb "$SOLVE" --out "$ORACLE" > "$OUT/oracle.log" 2>&1
COMMON="--task $TASK --env-num-envs 64 --env-num-threads 1 --env-seed 0 --num-steps-per-env 24 --save-interval $SAVE_INTERVAL --out $OUT"
for name in "${!SPECS[@]}"; do
  (
    if [ -f "$OUT/$name/config.json" ]; then
      a2cf-mb train --resume "$OUT/$name" --iterations "$ITERS"
    else
      a2cf-mb train --run-name "$name" ${SPECS[$name]//\$ORACLE/$ORACLE} --iterations "$ITERS" $COMMON
    fi > "$OUT/$name.log" 2>&1
    a2cf-mb eval "$OUT/$name" --num-envs 64 --seed 1 > "$OUT/$name-eval.log" 2>&1
    cp "$OUT/$name/eval.json" "$OUT/$name/eval_it$ITERS.json"
  ) &
done
wait
a2cf-mb compare "${RUN_ORDER[@]/#/$OUT/}" --out "$OUT" ${COMPARE_FLAGS:-}
