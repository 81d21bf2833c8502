#!/usr/bin/env bash
# Copy the walk_kinds runs' records into this folder with each run's last checkpoint (a later
# session continues them: restore_runs.sh docs/results/walk_kinds runs/walk_kinds, then
# `a2cf-mb train --resume runs/walk_kinds/<run>`), and summarise them (summary.json, curves.png).
# Usage: collect.sh [RUN_PARENT]   (default runs/walk_kinds)
set -euo pipefail
DST=$(dirname "$0")
SRC=${1:-runs/walk_kinds}
KEEP_LAST=1 SKIP="metrics.json policy.json" bash "$DST/../copy_runs.sh" "$SRC" "$DST"
python "$DST/summarise.py" "$SRC"/walkkinds_*/ --out "$DST"
