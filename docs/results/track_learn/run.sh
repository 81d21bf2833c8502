#!/usr/bin/env bash
# "Motion tracking that tracks" (issue 31): the track recipe (rl/tasks/track) on the built-in dance
# (`--task dance` = `track` on "builtin", 19 s, 0.28 rad mean |q - q_stand|), baseline (no help),
# 128 envs x 24 steps, 3256 iterations = 10.0 M env steps, evaluated alone every 60 iterations
# (32 fresh envs, seed 10000, from the dance's first frame). One physics and one torch thread per
# run; the three seeds ran at once on the 2-core machine.
# Usage: bash docs/results/track_learn/run.sh [baseline|residual|jointterm|a2cf_warm|lafan_oracle|lafan_baseline]
# (a2cf_warm, lafan_baseline: SEED=0 by default; the lafan cases: CLIP=path of the segment)   (OUT=runs/track_learn by default)
# Continue a run cut off by the end of a session: a2cf-mb train --resume "$OUT/<run>"
set -euo pipefail
OUT=${OUT:-runs/track_learn}
export OMP_NUM_THREADS=1
# The runs of Dec 4 before the residual probe (baseline, a2cf_warm, lafan_baseline) had the actions
# around the standing pose, the default then: `standing` reproduces them (the default is now around
# the reference).
standing=(--no-task-actions-around-reference)
common=(--num-envs 128 --env-num-threads 1 --save-interval 60 --eval-interval 60 --iterations 3256 --out "$OUT")
case "${1:-baseline}" in
baseline)
  for seed in 0 1 2; do
    a2cf-mb train --task dance --mode baseline --seed "$seed" "${common[@]}" "${standing[@]}" \
      --run-name "dance_baseline_s$seed" &
  done
  wait ;;
residual)  # the probe that tracks: PD targets around the reference (q_ref + scale a), 3 seeds
  for seed in 0 1 2; do
    a2cf-mb train --task dance --mode baseline --seed "$seed" "${common[@]}" \
      --task-actions-around-reference --run-name "dance_residual_s$seed" &
  done
  wait ;;
jointterm)  # the other probe: a steep joint term exp(-rms^2 / 0.2^2) at weight 2 (seed 0)
  a2cf-mb train --task dance --mode baseline --seed 0 "${common[@]}" \
    "${standing[@]}" --task-reward-weight joint_position=2 --run-name dance_jointterm_s0 ;;
a2cf_warm)  # A2CF with its force agent warm-started from the same dance's oracle (eta0, coach)
  seed=${SEED:-0}
  [ -d "$OUT/oracle_dance" ] || a2cf-mb solve-dance --out "$OUT/oracle_dance" --no-progress
  a2cf-mb train --task dance --mode a2cf --warmstart "$OUT/oracle_dance" --seed "$seed" "${common[@]}" "${standing[@]}" \
    --run-name "dance_a2cfwarm_s$seed" ;;
lafan_baseline)  # a 20 s segment of a public LAFAN1 G1 dance (never committed: LAFAN1 is CC BY-NC-ND).
  # Source: lvhaidong/LAFAN1_Retargeting_Dataset g1/dance1_subject2.csv (3945 rows, 30 fps), read
  # from the public mirror github.com/zzzb2002/adam_decouplewbc src/assets/motions/g1/; rows
  # 122-721 (whole_body_tracking's --frame_range 122 722 for this clip) written to their own
  # file, so the oracle and the task share one reference (the warm start checks its fingerprint):
  #   sed -n '123,722p' dance1_subject2.csv > dance1_subject2_f122-722.csv
  CLIP=${CLIP:?set CLIP to the 600-row segment file}
  seed=${SEED:-0}
  a2cf-mb train --task track --reference "$CLIP" --mode baseline --seed "$seed" "${common[@]}" "${standing[@]}" \
    --run-name "lafan_baseline_s$seed" ;;
lafan_oracle)
  CLIP=${CLIP:?set CLIP to the 600-row segment file}
  a2cf-mb solve-dance --clip "$CLIP" --out "$OUT/oracle_lafan_dance1s2_122-722" --no-video --no-progress ;;
*) echo "unknown case $1" >&2; exit 2 ;;
esac
