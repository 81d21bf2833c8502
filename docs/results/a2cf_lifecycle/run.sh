#!/usr/bin/env bash
# "A2CF measured where skills learn" (issue 21): baseline, a2cf and a2cf + warm start, same envs
# (128 x 24 steps), seed and budget per task, judged by the motion policy alone during training
# (32 fresh envs, seed 10000, every 40 iterations). One physics thread and one torch thread per
# run (OMP_NUM_THREADS=1): two runs at a time shared the 2-core machine.
# The dance baselines are the runs of docs/results/skills_learn (same code path for mode baseline).
# Usage: SEED=0 bash docs/results/a2cf_lifecycle/run.sh [dance|stand|stand3|stand3_ablations|dance3|dance3_update21]
# (no dance ablations: dance's eta0 is 40 on every axis, so no-id trains exactly as a2cf)
set -euo pipefail
OUT=${OUT:-runs/a2cf_lifecycle}
SEED=${SEED:-0}
export OMP_NUM_THREADS=1
# The runs named a2cf / a2cfwarm ran before the default became weaning: their trigger was the
# alone envs at 0.8 (OLD); the a2cfwean runs are the weaning default of Dec 2. Every run before
# stand3 ran before the fixed schedule became the default (200): they give 0 (NOSCHED).
# Every run but dance3_*21kl_* set the learning rate by the joint action's KL (KLALL).
KLALL=(--ppo-kl-actions all)
OLD=(--curriculum-skill-measure alone --curriculum-skill-learned-progress 0.8 --curriculum-anneal-iterations 0 "${KLALL[@]}")
NOSCHED=(--curriculum-anneal-iterations 0 "${KLALL[@]}")
common=(--num-envs 128 --seed "$SEED" --env-num-threads 1 --save-interval 40 --eval-interval 40 --out "$OUT")
case "${1:-dance}" in
dance)  # 650 iterations = 2.0 M env steps (the baselines reached the target at 1.47-1.72 M)
  a2cf-mb solve-dance --out "$OUT/oracle_dance" --no-video --overwrite
  a2cf-mb train --task dance --mode a2cf --iterations 650 "${common[@]}" "${OLD[@]}" --run-name "dance_a2cf_s$SEED" &
  a2cf-mb train --task dance --mode a2cf --iterations 650 "${common[@]}" "${OLD[@]}" --run-name "dance_a2cfwarm_s$SEED" \
    --warmstart "$OUT/oracle_dance" --curriculum-force-measure quantile &
  wait
  a2cf-mb train --task dance --mode a2cf --iterations 650 "${common[@]}" --run-name "dance_a2cfwean_s$SEED" "${NOSCHED[@]}" ;;
stand)  # 977 iterations = 3.0 M env steps (the budget); no stand oracle exists (standing
  # still needs no wrench): the warm start distils the built-in as-needed posture coach
  a2cf-mb train --task stand --mode a2cf --iterations 977 "${common[@]}" "${OLD[@]}" --run-name "stand_a2cf_s$SEED" &
  a2cf-mb train --task stand --mode a2cf --iterations 977 "${common[@]}" --run-name "stand_a2cfwean_s$SEED" "${NOSCHED[@]}" &
  wait ;;  # a warm-started stand run (--warmstart posture) was not made
stand3)  # Dec 3, today's recipe (stand: discount 0.995, 2 PPO + 1 encoder pass; a2cf: weaning by
  # the helped skill at 0.6, alone envs observe a zero bound) without and with the fixed schedule
  # (--curriculum-anneal-iterations 200, the default since); baselines skills_learn/
  # stand_nofc_g995_fast_s*. A run not at the target after 650 iterations (2.0 M) was continued to
  # 977 (3.0 M): a2cf-mb train --resume "$OUT/<run>" --iterations 977 (s0, s1 of stand3_a2cf; s1
  # of stand3_anneal).
  a2cf-mb train --task stand --mode a2cf --iterations 650 "${common[@]}" --run-name "stand3_a2cf_s$SEED" \
    --curriculum-anneal-iterations 0 "${KLALL[@]}" &
  a2cf-mb train --task stand --mode a2cf --iterations 650 "${common[@]}" --run-name "stand3_anneal_s$SEED" \
    --curriculum-anneal-iterations 200 "${KLALL[@]}" &
  wait ;;
stand3_ablations)  # the paper's ablations of the schedule variant on stand, 650 iterations each;
  # seeds 3 and 4 (no-id and the baseline only): SEED=3 bash run.sh stand3_ablations no-id
  for mode in ${2:-no-pi no-id no-rm}; do
    a2cf-mb train --task stand --mode "$mode" --iterations 650 "${common[@]}" \
      --run-name "stand3_anneal_${mode}_s$SEED" --curriculum-anneal-iterations 200 "${KLALL[@]}" &
  done
  [ "$SEED" -ge 3 ] && a2cf-mb train --task stand --mode baseline --iterations 650 "${common[@]}" \
    --run-name "stand_baseline_s$SEED" &
  wait ;;
dance3)  # Dec 3: the schedule alone and with the oracle's warm start (650 iterations, 2.0 M), and
  # (seed 0) the baseline with stand's lighter update, the demo's (2 PPO + 1 encoder pass)
  a2cf-mb solve-dance --out "$OUT/oracle_dance" --no-video --overwrite
  a2cf-mb train --task dance --mode a2cf --iterations 650 "${common[@]}" --run-name "dance3_anneal_s$SEED" \
    --curriculum-anneal-iterations 200 "${KLALL[@]}" &
  a2cf-mb train --task dance --mode a2cf --iterations 650 "${common[@]}" --run-name "dance3_warmanneal_s$SEED" \
    --warmstart "$OUT/oracle_dance" --curriculum-anneal-iterations 200 "${KLALL[@]}" &
  [ "$SEED" = 0 ] && a2cf-mb train --task dance --mode baseline --iterations 480 "${common[@]}" \
    --run-name "dance3_base21_s$SEED" --ppo-num-learning-epochs 2 --model-vae-learning-epochs 1 &
  wait ;;
dance3_update21)  # Dec 4: stand's update (2 PPO + 1 encoder pass, the demo's), 480 iterations
  # (1.47 M): baseline, a2cf and a2cf + warm start; seed 0 also with the learning rate set by the
  # joint action's KL (--ppo-kl-actions all, the default before: runs dance3_a2cf21_s0,
  # dance3_warm21_s0)
  U=(--ppo-num-learning-epochs 2 --model-vae-learning-epochs 1)
  S=(--curriculum-anneal-iterations 200 --ppo-kl-actions motion)
  a2cf-mb solve-dance --out "$OUT/oracle_dance" --no-video --overwrite
  a2cf-mb train --task dance --mode baseline --iterations 480 "${common[@]}" "${U[@]}" --run-name "dance3_base21_s$SEED" &
  a2cf-mb train --task dance --mode a2cf --iterations 480 "${common[@]}" "${U[@]}" "${S[@]}" --run-name "dance3_a2cf21kl_s$SEED" &
  a2cf-mb train --task dance --mode a2cf --iterations 480 "${common[@]}" "${U[@]}" "${S[@]}" --run-name "dance3_warm21kl_s$SEED" \
    --warmstart "$OUT/oracle_dance" &
  wait ;;
esac
# The learning-rate probe of dance's update (learning_rates.json: base55, a2cf55, base21, a2cf21),
# 30 iterations each, seed 0, out runs/probe:
#   a2cf-mb train --task dance --mode baseline|a2cf --iterations 30 "${common[@]}" --eval-interval 0 \
#     --out runs/probe --run-name base55|a2cf55 [--ppo-num-learning-epochs 2 --model-vae-learning-epochs 1: base21|a2cf21]
# (the probe ran before --ppo-kl-actions existed: the joint action's KL)
# then: python docs/results/a2cf_lifecycle/learning_rates.py RUN... --out learning_rates.json
# Stand with the recipe that learns (Dec 3; the code before it became stand's default, so its
# flags are given; runs stand2_*): the default a2cf (weaning) and the posture warm start.
#   R=(--task-reward-weight feet_contact=0 --ppo-gamma 0.995 --ppo-num-learning-epochs 5 --model-vae-learning-epochs 0)
#   a2cf-mb train --task stand --mode a2cf --iterations 977 "${common[@]}" "${R[@]}" "${NOSCHED[@]}" --run-name "stand2_a2cfwean_s$SEED"
#   a2cf-mb train --task stand --mode a2cf --iterations 977 "${common[@]}" "${R[@]}" "${NOSCHED[@]}" --run-name "stand2_a2cfwarm_s$SEED" \
#     --warmstart posture --curriculum-force-measure quantile
