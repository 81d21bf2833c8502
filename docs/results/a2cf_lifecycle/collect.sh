#!/usr/bin/env bash
# Copy the figures of the lifecycle runs (no checkpoints, no TensorBoard events; metrics.json and
# curriculum.jsonl packed by ../pack_record.py) into this folder, then summarise them with the baselines of
# docs/results/skills_learn: collect.sh RUN_PARENT (default runs/a2cf_lifecycle).
set -euo pipefail
SRC=${1:-runs/a2cf_lifecycle}
DST=$(dirname "$0")
BASE="$DST/../skills_learn"
for run in "$SRC"/*/; do
  name=$(basename "$run")
  [ -f "$run/config.json" ] || continue
  mkdir -p "$DST/$name"
  for f in config.json git.json evals.jsonl warmstart.json policy.json; do
    [ -f "$run/$f" ] && cp "$run/$f" "$DST/$name/"
  done
  for f in metrics.json curriculum.jsonl; do
    [ -f "$run/$f" ] && python3 "$DST/../pack_record.py" "$run/$f" "$DST/$name/$f.gz"
  done
done
# from the copies here (metrics.json.gz is read as is): the figures need nothing outside the repo
python "$DST/summarise.py" "$BASE"/dance_baseline_s{0,1,2} "$BASE"/stand_baseline_n128_s0 \
  "$DST"/{dance,stand}_a2cf*/ --out "$DST"
# Dec 3, today's defaults: stand against the baselines of the recipe that learns (same code path
# for mode baseline), and the dance baseline with the demo's lighter update against the 5 + 5 ones
if compgen -G "$DST/stand3_*/" > /dev/null; then
  python "$DST/summarise.py" "$BASE"/stand_nofc_g995_fast_s{0,1,2} "$DST"/stand3_a2cf_s*/ \
    "$DST"/stand3_anneal_s*/ --out "$DST/stand3"
  # the paper's ablations of the schedule variant (no-pi, no-id, no-rm), seeds 0-2
  python "$DST/summarise.py" "$BASE"/stand_nofc_g995_fast_s{0,1,2} "$DST"/stand3_anneal_s*/ \
    "$DST"/stand3_anneal_no-*_s[012]/ --out "$DST/stand3_ablations"
  # no-id, the ablation ahead on seeds 0-2, and the baseline on two more seeds (3, 4: same
  # recipe, 650 iterations)
  if compgen -G "$DST/stand_baseline_s*/" > /dev/null; then
    python "$DST/summarise.py" "$BASE"/stand_nofc_g995_fast_s{0,1,2} "$DST"/stand_baseline_s*/ \
      "$DST"/stand3_anneal_no-id_s*/ --out "$DST/stand3_no-id_5seeds"
  fi
fi
if compgen -G "$DST/dance3_*/" > /dev/null; then
  # dance's update (5 PPO + 5 encoder passes): the schedule, without and with the warm start
  python "$DST/summarise.py" "$BASE"/dance_baseline_s{0,1,2} "$DST"/dance3_anneal_s*/ \
    "$DST"/dance3_warmanneal_s*/ --out "$DST/dance3"
  # stand's update (2 + 1, the demo's): baseline, a2cf and a2cf + warm start, the learning rate
  # set by the joint action's KL (seed 0) and by the motion actions' (today's default)
  python "$DST/summarise.py" "$DST"/dance3_base21_s*/ "$DST"/dance3_a2cf21*_s*/ \
    "$DST"/dance3_warm21*_s*/ --out "$DST/dance3_update21"
fi
