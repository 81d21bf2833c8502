#!/usr/bin/env bash
# Copy the backflip_track runs' records (no checkpoints) into this folder: collect.sh [RUN_PARENT]
set -euo pipefail
DST=$(dirname "$0")
bash "$DST/../copy_runs.sh" "${1:-runs/backflip_track}" "$DST"
