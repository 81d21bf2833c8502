#!/usr/bin/env bash
# Copy the track_learn runs' figures (no checkpoints, no TensorBoard events; metrics.json packed by ../pack_record.py)
# into this folder and summarise them: collect.sh [RUN_PARENT] (default runs/track_learn).
set -euo pipefail
SRC=${1:-runs/track_learn}
DST=$(dirname "$0")
bash "$DST/../copy_runs.sh" "$SRC" "$DST"
# the default recipe (actions around the reference), 3 seeds: summary, curves and the seed spread
# the demo reads; the same baseline with the actions around the standing pose: standing/
python "$DST/summarise.py" "$DST"/dance_residual_s{0,1,2} --out "$DST"
python "$DST/summarise.py" "$DST"/dance_baseline_s{0,1,2} --out "$DST/standing"
if [ -d "$DST/dance_a2cfwarm_s0" ]; then
  python "$DST/summarise.py" "$DST"/dance_baseline_s0 "$DST"/dance_a2cfwarm_s0 --out "$DST/a2cf_vs_baseline_s0"
fi
if [ -d "$DST/dance_residual_s0" ]; then  # the probes against the baseline, seed 0; the 3 seeds
  python "$DST/summarise.py" "$DST"/dance_baseline_s0 "$DST"/dance_residual_s0 \
    $( [ -d "$DST/dance_jointterm_s0" ] && echo "$DST/dance_jointterm_s0" ) --out "$DST/probes_s0"
fi
if [ -d "$DST/lafan_baseline_s0" ]; then
  python "$DST/summarise.py" "$DST"/lafan_baseline_s0 --out "$DST/lafan"
fi
