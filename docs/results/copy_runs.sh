#!/usr/bin/env bash
# Copy the run folders under SRC into DST as study records: each run's config.json, git.json,
# branch.json, evals*.jsonl, warmstart.json, policy.json, metrics.json and curriculum.jsonl
# (packed), and each oracle artifact's oracle.json (its reference and arrays stay out: a clip may
# not be ours).
# No TensorBoard events, and no checkpoints unless KEEP_LAST=1: then each run's last checkpoint
# (checkpoints/last.pt, ~4 MB) and its live logs (metrics.jsonl, curriculum.jsonl) come too, so a
# later session on a fresh machine continues the run exactly: restore_runs.sh DST runs/<study>, then
# a2cf-mb train --resume runs/<study>/<run>. SKIP="metrics.json policy.json" leaves those files out
# (their size counts against what a GPU visit carries). A branch (branch.json) keeps only its own
# metrics.jsonl rows, from its branch iteration on: its parent's record holds the rest.
# Packed by pack_record.py: floats to 6 significant digits, gzipped with no name or time in the
# header, so an unchanged log packs byte for byte.
# Usage: [KEEP_LAST=1 [KEEP_ONLY="RUN..."]] [SKIP="FILE..."] copy_runs.sh SRC DST
set -euo pipefail
SRC=$1
DST=$2
for run in "$SRC"/*/; do
  name=$(basename "$run")
  [ -f "$run/config.json" ] || continue
  mkdir -p "$DST/$name"
  for f in config.json git.json branch.json evals.jsonl evals_checkpoints.jsonl warmstart.json policy.json; do
    [[ " ${SKIP:-} " == *" $f "* ]] && continue
    [ -f "$run/$f" ] && cp "$run/$f" "$DST/$name/"
  done
  pack="python3 $(dirname "$0")/pack_record.py"
  if [ -f "$run/metrics.json" ] && [[ " ${SKIP:-} " != *" metrics.json "* ]]; then
    $pack "$run/metrics.json" "$DST/$name/metrics.json.gz"
  fi
  [ -f "$run/curriculum.jsonl" ] && $pack "$run/curriculum.jsonl" "$DST/$name/curriculum.jsonl.gz"
  if [ -f "$run/metrics.jsonl" ]; then
    # a branch keeps its own rows only, from its branch iteration on
    start=$(python3 -c 'import json,sys
try: print(json.load(open(sys.argv[1]))["iteration"])
except (OSError, ValueError, KeyError, TypeError): pass' "$run/branch.json")
    $pack "$run/metrics.jsonl" "$DST/$name/metrics.jsonl.gz" ${start:+--from-iteration "$start"}
  fi
  keep=${KEEP_LAST:-0}
  # KEEP_ONLY="run_a run_b": of the runs, only these keep their checkpoint (the tracked tree is
  # what a GPU visit carries: docs/gpu.md)
  if [ -n "${KEEP_ONLY:-}" ] && [[ " $KEEP_ONLY " != *" $name "* ]]; then keep=0; fi
  if [ "$keep" = "1" ] && [ -f "$run/checkpoints/last.pt" ]; then
    mkdir -p "$DST/$name/checkpoints"
    cp "$run/checkpoints/last.pt" "$DST/$name/checkpoints/last.pt"
  fi
done
for art in "$SRC"/oracle*/; do
  [ -f "$art/oracle.json" ] || continue
  mkdir -p "$DST/$(basename "$art")"
  cp "$art/oracle.json" "$DST/$(basename "$art")/"
done
