#!/usr/bin/env bash
# Copy the figures of the skills-that-learn runs (no checkpoints, no TensorBoard events) into this
# folder (metrics.json packed by ../pack_record.py: the studies read it as is), then summarise them: collect.sh
# RUN_PARENT (default runs/skills_learn).
set -euo pipefail
SRC=${1:-runs/skills_learn}
DST=$(dirname "$0")
for run in "$SRC"/*/; do
  name=$(basename "$run")
  mkdir -p "$DST/$name"
  [ -f "$run/metrics.json" ] && python3 "$DST/../pack_record.py" "$run/metrics.json" "$DST/$name/metrics.json.gz"
  for f in config.json git.json evals.jsonl evals_checkpoints.jsonl eval*.json \
           walk_eval.json walk_eval.png eval_dance.png policy.json; do
    [ -f "$run/$f" ] && cp "$run/$f" "$DST/$name/"
  done
done
python "$DST/summarise.py" "$SRC"/*/ --out "$DST"
