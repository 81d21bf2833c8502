#!/usr/bin/env bash
# Copy the walk_flat runs' records into this folder, with each run's last checkpoint so that a
# later session continues it (restore_runs.sh docs/results/walk_flat runs/walk_flat, then
# `a2cf-mb train --resume runs/walk_flat/<run>`), and draw the study: study.json / study.png
# (env steps to the target, survival and velocity error alone against env steps) and
# lifecycle_walk-flat.png (A2CF's bound and applied force beside the evaluations alone).
# Usage: collect.sh [RUN_PARENT]   (default runs/walk_flat)
set -euo pipefail
DST=$(dirname "$0")
SRC=${1:-runs/walk_flat}
# Only the seed-0 baseline keeps its checkpoint (each is 5-7 MB of the tree a GPU visit carries);
# no metrics.json or policy.json per run (the records' rows and the confirmed exports hold them)
KEEP_LAST=1 KEEP_ONLY=${KEEP_ONLY:-walkflat_baseline_128_s0} SKIP="metrics.json policy.json" bash "$DST/../copy_runs.sh" "$SRC" "$DST"
runs=()
for rec in "$DST"/walkflat_*_128_s*/; do
  [ -f "$rec/config.json" ] && runs+=("$rec")
done
python "$DST/../a2cf_lifecycle/summarise.py" "${runs[@]}" --out "$DST"
