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
  # built beside its place and moved there whole: a killed restore leaves no half folder that a
  # rerun would skip
  tmp="$DST/.$name.restoring"
  rm -rf "$tmp"
  mkdir -p "$tmp/checkpoints"
  cp "$rec/checkpoints/last.pt" "$tmp/checkpoints/"
  for f in config.json git.json branch.json evals.jsonl evals_checkpoints.jsonl warmstart.json; do
    if [ -f "$rec/$f" ]; then cp "$rec/$f" "$tmp/"; fi
  done
  for f in curriculum.jsonl metrics.jsonl; do
    if [ -f "$rec/$f.gz" ]; then gunzip -c "$rec/$f.gz" > "$tmp/$f"; fi
  done
  mv "$tmp" "$DST/$name"
  echo "restore_runs: $DST/$name (resume with a2cf-mb train --resume $DST/$name)"
done
