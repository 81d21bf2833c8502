"""The novice model answers at every frame: soft joint rows, help causes per phase, eta0 of the
backflip's Jump phase, eta0 stable across cold and warm TO solves."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from optimal_control.artifact import build_artifact
from optimal_control.bounds import BoundRule
from optimal_control.reference import NV, static_reference
from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig
from robots import g1


def _squat_pose(robot):
    """A deep squat on both soles, heavy on knees and hips."""
    import pinocchio as pin

    q = robot.q_stand.copy()
    idx = {name: robot.joint_q_index[i] for i, name in enumerate(g1.JOINT_NAMES)}
    for side in ("left", "right"):
        q[idx[f"{side}_hip_pitch_joint"]] = -1.3
        q[idx[f"{side}_knee_joint"]] = 2.2
        q[idx[f"{side}_ankle_pitch_joint"]] = -0.85
    data = robot.data()
    pin.framesForwardKinematics(robot.model, data, q)
    q[2] -= min(data.oMf[robot.frame_ids[s]].translation[2] for s in g1.SOLE_FRAMES)
    return q


def test_too_weak_frames_are_answered_not_dropped(g1_pin):
    q = _squat_pose(g1_pin)
    hard = WrenchQP(WrenchQPConfig(alpha=0.05, soft_joint_rows=False))
    soft = WrenchQP(WrenchQPConfig(alpha=0.05))
    h = hard.solve(q, np.zeros(NV), np.zeros(NV), (True, True))
    s = soft.solve(q, np.zeros(NV), np.zeros(NV), (True, True))
    assert not h.solved  # the former model drops this frame
    assert s.solved and s.residual < 1e-4  # the base rows hold exactly
    assert np.all(np.abs(s.tau_nm) <= 0.05 * g1.EFFORT_LIMIT_NM + 1e-4)
    assert np.abs(s.missing_torque_nm).max() > 0.5  # a limb lacks torque
    assert np.linalg.norm(s.wrench_w) > 10.0  # and the pelvis helps


def test_soft_rows_keep_the_hard_answer_where_it_exists(g1_pin, rng):
    q = _squat_pose(g1_pin)
    a = rng.normal(0.0, 0.5, NV)
    hard = WrenchQP(WrenchQPConfig(alpha=1.0, soft_joint_rows=False))
    soft = WrenchQP(WrenchQPConfig(alpha=1.0))
    h = hard.solve(q, np.zeros(NV), a, (True, True))
    s = soft.solve(q, np.zeros(NV), a, (True, True))
    assert h.solved and s.solved
    np.testing.assert_allclose(s.wrench_w, h.wrench_w, atol=1e-6)
    np.testing.assert_allclose(s.missing_torque_nm, 0.0, atol=1e-3)  # ~1e-6 tau: regularisation


def test_help_causes_per_phase(g1_pin):
    # Phase 0: a squat on both soles (help only from weakness); phase 1: the same pose in the air
    # (help the motion itself needs, at any strength).
    ref = static_reference(_squat_pose(g1_pin), 10, 0.02)
    ref = dataclasses.replace(
        ref,
        phase=np.repeat([0, 1], 5),
        phase_names=("squat", "flying"),
        contacts=ref.contacts.copy(),
    )
    ref.contacts[5:] = False
    profiles = {a: WrenchQP(WrenchQPConfig(alpha=a)).solve_reference(ref) for a in (1.0, 0.05)}
    assert all(p.solved.all() for p in profiles.values())
    art = build_artifact("test", ref, profiles, BoundRule(novice_alpha=0.05))
    causes = art.summary()["help_causes"]
    assert causes["squat"]["torque_deficit_share"] > 0.9
    assert causes["flying"]["motion_share"] > 0.5
    assert causes["squat"]["lagging_frame_share"] > 0.0  # at 0.05 x tau_max the knees lack torque
    assert art.eta0[0, 2] > BoundRule().floor_force_n  # the weak squat gets help, not the floor


@pytest.mark.slow
def test_hop_jump_gets_help_and_eta0_is_the_same_cold_and_warm():
    """Tiny hop (the flip's NLP on a coarse grid, no turn): solved cold, then warm from the cold
    solution and from a perturbed one (a nearby optimum); eta0 of the novice (alpha 0.5)."""
    from optimal_control.backflip.config import tiny_hop_config
    from optimal_control.backflip.sagittal import build_sagittal_model
    from optimal_control.backflip.solve import solve_backflip_to
    from optimal_control.backflip.trajectory import fine_grid_limit_report, sample_solution
    from optimal_control.oracle import OracleConfig, sweep_alphas

    cfg = dataclasses.replace(tiny_hop_config(), max_iter=200, cache_dir="")
    model = build_sagittal_model()
    cold = solve_backflip_to(cfg, model)
    nudged = dataclasses.replace(cold.solution, r=cold.solution.r + 0.01)
    warm = solve_backflip_to(cfg, model, warm_start=nudged)
    oc = OracleConfig(alphas=(1.0, 0.5), progress=False)
    eta = []
    for res in (cold, warm):
        ref = sample_solution(res.solution, res.transcription.grid, model, 50.0).to_reference()
        profiles, _ = sweep_alphas(ref, oc)
        assert all(p.solved.all() for p in profiles.values())
        eta.append(build_artifact("backflip", ref, profiles, oc.rule()).eta0)
    jump = 2
    assert eta[0][jump, 2] > 2 * BoundRule().floor_force_n, eta[0]  # Jump no longer at the floor
    np.testing.assert_allclose(eta[1], eta[0], rtol=0.2, atol=3.0)
    # Limits on a 1 kHz grid: at least the knots' worst effort ratio, named joint and phase.
    limits = fine_grid_limit_report(cold.solution, cold.transcription.grid, model)
    knot = sample_solution(cold.solution, cold.transcription.grid, model, 50.0)
    assert (
        limits["effort"]["max_ratio"] >= np.max(np.abs(knot.tau_nm) / model.effort_limit_nm) - 1e-9
    )
    assert limits["samples"] > 10 * knot.time_s.shape[0]
    assert limits["speed"]["joint"] in g1.JOINT_NAMES
