#!/usr/bin/env bash
# A run's checkpoint K as a run of its own, exported: OUT/<run>_itK holds the run's config and
# model_K.pt as its last checkpoint, resumed to iteration K (nothing to train: it writes the
# policy.onnx and the deployment bundle of that checkpoint), for eval --sim2sim and videos.
# Prints the new run folder. Usage: export_checkpoint.sh RUN_DIR K OUT
set -euo pipefail
run=$1
k=$2
out=$3
name=$(basename "$run")_it$k
mkdir -p "$out"
rm -rf "${out:?}/$name"
mkdir -p "$out/$name/checkpoints"
for f in config.json git.json warmstart.json; do
  [ -f "$run/$f" ] && cp "$run/$f" "$out/$name/"
done
cp "$run/checkpoints/model_$k.pt" "$out/$name/checkpoints/last.pt"
a2cf-mb train --resume "$out/$name" --iterations "$k" > "$out/$name/export.log" 2>&1
echo "$out/$name"
