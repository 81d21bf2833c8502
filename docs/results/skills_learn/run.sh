#!/usr/bin/env bash
# "Skills that learn" (issue 19): the baseline recipes of stand, dance and walk-flat, judged by the
# motion policy alone (assistance off, 32 fresh envs, seed 10000, one episode each).
# Each run uses one physics thread and one torch thread (OMP_NUM_THREADS=1): three runs shared the
# 2-core machine. Runs that outlast a session continue with `a2cf-mb train --resume RUN`.
set -euo pipefail
OUT=${OUT:-runs/skills_learn}
SEED=${SEED:-0}
export OMP_NUM_THREADS=1
# stand: 128 envs x 24 steps, 977 iterations = 3.0 M env steps (target: >= 90 % survival).
# Today's default recipe (no feet_contact, discount 0.995, 2 PPO + 1 encoder passes) ran on the
# previous code with its flags (runs stand_nofc_g995_fast_s0..2); the same command without them
# trains it now. The earlier recipes: the old default (stand_baseline_n128_s0; 512 envs:
# stand_baseline_s0), and discount 0.995 without feet_contact with 5 passes (stand_nofc_g995_s*):
#   --task-reward-weight feet_contact=0 --ppo-gamma 0.995 [--ppo-num-learning-epochs 5 --model-vae-learning-epochs 0]
a2cf-mb train --task stand --mode baseline --num-envs 128 --seed "$SEED" --env-num-threads 1 \
  --iterations 977 --save-interval 40 --eval-interval 40 --out "$OUT" --run-name "stand_nofc_g995_fast_s$SEED"
# dance: 128 envs x 24 steps (target: skill error < 0.16 rad). Budget 5 M = 1628 iterations; the
# session's runs stopped at 525 (seed 0, eval every 80) and 651 / 658 iterations (seeds 1, 2, eval
# every 40): stop a run with Ctrl-C, then `a2cf-mb train --resume RUN --iterations K` exports it.
a2cf-mb train --task dance --mode baseline --num-envs 128 --seed "$SEED" --env-num-threads 1 \
  --iterations 1628 --save-interval 40 --eval-interval 40 --out "$OUT" --run-name "dance_baseline_s$SEED"
# final policies: a2cf-mb eval RUN --num-envs 32 --sim2sim (stand, dance), and (dance) --num-envs 128 --seed 2
# walk-flat: 512 envs x 24 steps, 2500 iterations = 30.7 M env steps (target: >= 90 % survival
# and mean velocity error <= 0.25 m/s); the session's run stopped at 512 iterations (6.3 M)
a2cf-mb train --task walk-flat --mode baseline --num-envs 512 --seed "$SEED" --env-num-threads 1 \
  --iterations 2500 --save-interval 10 --out "$OUT" --run-name "walkflat_baseline_s$SEED"
# runs trained without evaluations during training: evaluate their kept checkpoints
a2cf-mb eval-curve "$OUT/stand_baseline_s$SEED"  # the 512-env comparison run, every kept checkpoint
a2cf-mb eval-curve "$OUT/walkflat_baseline_s$SEED" --every-iterations 50
bash docs/results/skills_learn/collect.sh "$OUT"
