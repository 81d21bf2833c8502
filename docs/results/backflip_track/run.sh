#!/usr/bin/env bash
# "The backflip, learned by tracking the oracle's flip" (issue 34): the track task on a
# `solve-backflip` artifact (its phases read from the artifact, its ends held 1.5 s standing,
# reference state initialisation along the flip, evaluation from standing with the flip judge of
# rl/tasks/track/flip.py), PD targets around the reference (--task-actions-around-reference),
# 128 envs x 24 steps, 9766 iterations = 30.0 M env steps, evaluated alone every 60 iterations
# (32 fresh envs from standing). One physics and one torch thread per run.
# Usage: bash docs/results/backflip_track/run.sh [oracle|baseline|a2cf_warm|coach]   (SEED=0, OUT=runs/backflip_track, FEEDFORWARD=0, SHINS=0)
# Continue a run cut off by the end of a session: a2cf-mb train --resume "$OUT/<run>"
set -euo pipefail
OUT=${OUT:-runs/backflip_track}
seed=${SEED:-0}
export OMP_NUM_THREADS=1
# SHINS=1: the flip re-solved with its shins' collision boxes 1 cm off the floor at every knot
# (solve-backflip --shin-clearance; the default flip rests the boxes' corners by the ankles on the
# floor in both crouches, a support the URDF meshes do not give: sim2sim_gap.py); names get "_shins"
oracle="$OUT/oracle"; oracle_flags=(); shins=""
if [[ "${SHINS:-0}" == 1 ]]; then
  oracle="$OUT/oracle_shins"; oracle_flags=(--shin-clearance --min-shin-height-m 0.01); shins="_shins"
fi
common=(--task track --reference "$oracle" --task-actions-around-reference --num-envs 128
        --env-num-threads 1 --save-interval 60 --eval-interval 60 --iterations 9766 --out "$OUT")
# FEEDFORWARD=1: the oracle's feed-forward in the PD law (--task-action-feedforward: the TO's
# joint torques and the reference's joint rates; zero action is the oracle's own control); the
# run names get "_ff"
ff="$shins"
if [[ "${FEEDFORWARD:-0}" == 1 ]]; then common+=(--task-action-feedforward); ff+="_ff"; fi
# FLIGHT_FREE=1: the drift terminations (anchor tilt, end-effector height) off in the jump and
# the air (--task-drift-free-phases jump air); the run names get "_free"
if [[ "${FLIGHT_FREE:-0}" == 1 ]]; then common+=(--task-drift-free-phases jump air); ff+="_free"; fi
case "${1:-baseline}" in
oracle)  # the flip and its wrenches (about 3 min cold)
  a2cf-mb solve-backflip "${oracle_flags[@]}" --oracle-out "$oracle" --no-oracle-progress ;;
baseline)  # no help
  a2cf-mb train "${common[@]}" --mode baseline --seed "$seed" --run-name "flip${ff}_baseline_s$seed" ;;
a2cf_warm)  # A2CF, the force head warm-started from the artifact's coach, eta0 per phase from it;
  # the help annealed over 3000 iterations (9.2 M env steps; the default 200, measured best on
  # stand and dance, took all help away by 0.6 M, before any robot got past the crouch:
  # flip_a2cfwarm_anneal200_s0, ANNEAL=200)
  a2cf-mb train "${common[@]}" --mode a2cf --warmstart "$OUT/oracle" --seed "$seed" \
    --curriculum-anneal-iterations "${ANNEAL:-3000}" --run-name "flip${ff}_a2cfwarm_s$seed" ;;
coach)  # the artifact's coach itself as the help, scaled by the failure rate (ZEST's rule)
  a2cf-mb train "${common[@]}" --mode coach --coach-source "$OUT/oracle" --seed "$seed" \
    --run-name "flip${ff}_coach_s$seed" ;;
*) echo "unknown case $1" >&2; exit 2 ;;
esac
