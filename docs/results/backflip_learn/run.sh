#!/usr/bin/env bash
# Reduced backflip benchmark: baseline vs a2cf, same seed / envs / budget, run side by side
# (one physics thread each) in chunks of CHUNK iterations so metrics.json exists after each chunk.
# Usage: docs/results/backflip_learn/run.sh [MAX_ITERATIONS] [CHUNK] [DONE]
#   DONE > 0 continues existing runs (runs/backflip_learn/<mode>) from DONE completed iterations.
set -euo pipefail
MAX=${1:-400}
CHUNK=${2:-25}
DONE=${3:-0}
OUT=runs/backflip_learn
export OMP_NUM_THREADS=1
chunked() {
  local mode=$1 total=$DONE
  if [ "$total" -eq 0 ]; then
    total=$CHUNK
    .venv/bin/a2cf-mb train --task backflip --mode "$mode" --env-num-envs 64 --env-num-threads 1 \
      --env-seed 0 --iterations "$total" --out "$OUT" --run-name "$mode" --save-interval 1000
  fi
  while [ "$total" -lt "$MAX" ]; do
    total=$((total + CHUNK))
    .venv/bin/a2cf-mb train --resume "$OUT/$mode" --iterations "$total"
  done
}
chunked baseline >> "$OUT.baseline.log" 2>&1 &
chunked a2cf >> "$OUT.a2cf.log" 2>&1 &
wait
