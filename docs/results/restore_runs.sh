#!/usr/bin/env bash
# Rebuild resumable run folders from study records that copy_runs.sh wrote with KEEP_LAST=1 (the
# run folders under runs/ do not outlive a machine). Each record with checkpoints/last.pt becomes
# DST/<run> with its config, logs and last checkpoint; continue it with
#   a2cf-mb train --resume DST/<run> --iterations N
# A run folder that already exists in DST is left alone. Usage: restore_runs.sh SRC DST
set -euo pipefail
SRC=$1
DST=$2
for rec in "$SRC"/*/; do
  name=$(basename "$rec")
  [ -f "$rec/checkpoints/last.pt" ] || continue
  if [ -e "$DST/$name" ]; then
    echo "restore_runs: $DST/$name exists; left alone" >&2
    continue
  fi
  mkdir -p "$DST/$name/checkpoints"
  cp "$rec/checkpoints/last.pt" "$DST/$name/checkpoints/"
  for f in config.json git.json evals.jsonl evals_checkpoints.jsonl warmstart.json; do
    [ -f "$rec/$f" ] && cp "$rec/$f" "$DST/$name/"
  done
  for f in curriculum.jsonl metrics.jsonl; do
    [ -f "$rec/$f.gz" ] && gunzip -c "$rec/$f.gz" > "$DST/$name/$f"
  done
  echo "restore_runs: $DST/$name (resume with a2cf-mb train --resume $DST/$name)"
done
