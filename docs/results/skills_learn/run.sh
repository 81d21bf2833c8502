#!/usr/bin/env bash
# "Skills that learn" (issue 19): the baseline recipes of stand, dance and walk-flat, judged by the
# motion policy alone (assistance off, 32 fresh envs, seed 10000, one episode each).
# Each run uses one physics thread and one torch thread (OMP_NUM_THREADS=1): three runs shared the
# 2-core machine. Runs that outlast a session continue with `a2cf-mb train --resume RUN`.
set -euo pipefail
OUT=${OUT:-runs/skills_learn}
SEED=${SEED:-0}
export OMP_NUM_THREADS=1
# stand: 512 envs x 24 steps, 250 iterations = 3.07 M env steps (target: >= 90 % survival)
a2cf-mb train --task stand --mode baseline --num-envs 512 --seed "$SEED" --env-num-threads 1 \
  --iterations 250 --save-interval 10 --out "$OUT" --run-name "stand_baseline_s$SEED"
# dance: 128 envs x 24 steps, 1628 iterations = 5.0 M env steps (target: skill error < 0.16 rad)
a2cf-mb train --task dance --mode baseline --num-envs 128 --seed "$SEED" --env-num-threads 1 \
  --iterations 1628 --save-interval 40 --eval-interval 80 --out "$OUT" --run-name "dance_baseline_s$SEED"
# walk-flat: 512 envs x 24 steps, 2500 iterations = 30.7 M env steps (target: >= 90 % survival
# and mean velocity error <= 0.25 m/s)
a2cf-mb train --task walk-flat --mode baseline --num-envs 512 --seed "$SEED" --env-num-threads 1 \
  --iterations 2500 --save-interval 10 --out "$OUT" --run-name "walkflat_baseline_s$SEED"
# runs trained without evaluations during training: evaluate their kept checkpoints
for run in "$OUT"/*; do a2cf-mb eval-curve "$run"; done
python docs/results/skills_learn/summarise.py "$OUT"/* --out docs/results/skills_learn
