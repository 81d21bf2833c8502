#!/usr/bin/env bash
# Stand: baseline vs a2cf vs a2cf + warm start (as-needed posture coach), same seed, envs, budget;
# then each motion policy evaluated alone (assistance off) on 64 fresh envs. ~30-40 min on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/../../.."
OUT=runs/stand_warmstart
COMMON="--task stand --env-num-envs 64 --env-seed 0 --iterations 150 --num-steps-per-env 24 --save-interval 150 --out $OUT"
for spec in "baseline baseline" "a2cf a2cf" "a2cf_warm a2cf --warmstart posture"; do
  set -- $spec
  name=$1; shift
  [ -f "$OUT/$name/metrics.json" ] || .venv/bin/a2cf-mb train --run-name "$name" --mode $@ $COMMON > "$OUT-$name.log" 2>&1
  .venv/bin/a2cf-mb eval "$OUT/$name" --num-envs 64 --seed 1 > "$OUT-$name-eval.log" 2>&1
done
.venv/bin/python docs/results/stand_warmstart/summarise.py "$OUT" docs/results/stand_warmstart
