#!/usr/bin/env bash
# Issue 52: two 20 s segments of public LAFAN1 G1 dances, tracked with the oracle's parts.
# Usage: bash docs/results/clip_oracle/run.sh SEGMENT VARIANT [SEED]
#   SEGMENT: d1 (dance1_subject2 2700:3300) | d2 (dance2_subject3 2100:2700)
#   VARIANT: plain | ff | ff_a2cf | ff_coach          (SEED: 0 by default)
# The clips are never committed: CLIPS=/work/clips by default (README.md: where they come from).
# The first --oracle run of a segment solves its oracle into $OUT/oracle_cache/<fingerprint>/
# (about 20 s); the others wait for it and reuse it. Continue a cut-off run with
# a2cf-mb train --resume "$OUT/<run>".
set -euo pipefail
segment=${1:?d1 or d2}; variant=${2:?plain, ff, ff_a2cf or ff_coach}; seed=${3:-0}
CLIPS=${CLIPS:-/work/clips}; OUT=${OUT:-runs/clip_oracle}
case "$segment" in
d1) clip=(--reference "$CLIPS/dance1_subject2.csv" --reference-frames 2700:3300) ;;
d2) clip=(--reference "$CLIPS/dance2_subject3.csv" --reference-frames 2100:2700) ;;
*) echo "unknown segment $segment" >&2; exit 2 ;;
esac
# 128 envs x 24 steps = 3072 env steps per iteration: 6511 iterations = 20 M env steps
common=(--task track "${clip[@]}" --seed "$seed" --num-envs 128 --env-num-threads 1
        --save-interval 60 --eval-interval 60 --iterations 6511 --out "$OUT")
case "$variant" in
plain) extra=(--mode baseline) ;;
ff) extra=(--mode baseline --oracle --task-action-feedforward) ;;
ff_a2cf) extra=(--mode a2cf --oracle --task-action-feedforward --warmstart oracle) ;;
ff_coach) extra=(--mode coach --oracle --task-action-feedforward --coach-source oracle) ;;
*) echo "unknown variant $variant" >&2; exit 2 ;;
esac
exec a2cf-mb train "${common[@]}" "${extra[@]}" --run-name "${segment}_${variant}_s${seed}"
