#!/usr/bin/env bash
# Copy the run folders under SRC into DST as study records: each run's config.json, git.json,
# evals*.jsonl, warmstart.json, policy.json, metrics.json and curriculum.jsonl (gzipped), and each
# oracle artifact's oracle.json (its reference and arrays stay out: a clip may not be ours).
# No checkpoints, no TensorBoard events. Usage: copy_runs.sh SRC DST
set -euo pipefail
SRC=$1
DST=$2
for run in "$SRC"/*/; do
  name=$(basename "$run")
  [ -f "$run/config.json" ] || continue
  mkdir -p "$DST/$name"
  for f in config.json git.json evals.jsonl evals_checkpoints.jsonl warmstart.json policy.json; do
    [ -f "$run/$f" ] && cp "$run/$f" "$DST/$name/"
  done
  [ -f "$run/metrics.json" ] && gzip -c "$run/metrics.json" > "$DST/$name/metrics.json.gz"
  [ -f "$run/curriculum.jsonl" ] && gzip -c "$run/curriculum.jsonl" > "$DST/$name/curriculum.jsonl.gz"
done
for art in "$SRC"/oracle*/; do
  [ -f "$art/oracle.json" ] || continue
  mkdir -p "$DST/$(basename "$art")"
  cp "$art/oracle.json" "$DST/$(basename "$art")/"
done
