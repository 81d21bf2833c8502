#!/usr/bin/env bash
# Copy the backflip_track runs' records into this folder (no TensorBoard events); only the runs in
# KEEP_ONLY keep their last checkpoint (5-7 MB each of the tree a GPU visit carries: docs/gpu.md),
# so that a later session continues them (restore_runs.sh docs/results/backflip_track
# runs/backflip_track, then `a2cf-mb train --resume runs/backflip_track/<run>`); then draw the study
# (study.png, study.json: turn, flips landed and episode length alone against env steps).
# Usage: collect.sh [RUN_PARENT]   (default runs/backflip_track; KEEP_ONLY="flip_ff_baseline_s0")
set -euo pipefail
DST=$(dirname "$0")
KEEP_LAST=1 KEEP_ONLY=${KEEP_ONLY:-flip_ff_baseline_s0} bash "$DST/../copy_runs.sh" "${1:-runs/backflip_track}" "$DST"
# each record's live run folder where this machine has it: its TensorBoard events hold the help
SRC=${1:-runs/backflip_track}
runs=()
for rec in "$DST"/flip_*_s*/; do
  name=$(basename "$rec")
  if [ -f "$SRC/$name/evals.jsonl" ]; then runs+=("$SRC/$name"); elif [ -f "$rec/evals.jsonl" ]; then runs+=("$rec"); fi
done
python "$DST/study.py" "$DST" "${runs[@]}"
