#!/usr/bin/env bash
# Copy the figures of the lifecycle runs (no checkpoints, no TensorBoard events; metrics.json and
# curriculum.jsonl gzipped) into this folder, then summarise them with the baselines of
# docs/results/skills_learn: collect.sh RUN_PARENT (default runs/a2cf_lifecycle).
set -euo pipefail
SRC=${1:-runs/a2cf_lifecycle}
DST=$(dirname "$0")
BASE="$DST/../skills_learn"
for run in "$SRC"/*/; do
  name=$(basename "$run")
  [ -f "$run/config.json" ] || continue
  mkdir -p "$DST/$name"
  for f in config.json git.json evals.jsonl warmstart.json policy.json; do
    [ -f "$run/$f" ] && cp "$run/$f" "$DST/$name/"
  done
  for f in metrics.json curriculum.jsonl; do
    [ -f "$run/$f" ] && gzip -c "$run/$f" > "$DST/$name/$f.gz"
  done
done
# from the copies here (metrics.json.gz is read as is): the figures need nothing outside the repo
python "$DST/summarise.py" "$BASE"/dance_baseline_s{0,1,2} "$BASE"/stand_baseline_n128_s0 \
  "$DST"/{dance,stand}_*/ --out "$DST"
