"""The per-frame wrench QP: known answers, the MuJoCo wrench convention, warm start."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from optimal_control.reference import NV, static_reference
from optimal_control.wrench_qp import (
    NX,
    WrenchQP,
    WrenchQPConfig,
    generalized_force_of_pelvis_wrench,
    pelvis_com_offset_m,
    xfrc_applied_from_pelvis_wrench,
)
from robots import g1
from robots.conventions import pin_to_mj_qpos, velocity_map_pin_to_mj

GRAVITY = 9.81


def _weight_wrench_at_pelvis_com(robot, q):
    """Expected w with no contact: m g up at the CoM, moved to the pelvis CoM (world axes)."""
    data = robot.data()
    com_w = pin.centerOfMass(robot.model, data, q)
    pelvis_com_w = data.oMi[1].act(pelvis_com_offset_m(robot))
    force = np.array([0.0, 0.0, robot.total_mass_kg * GRAVITY])
    return np.concatenate([force, np.cross(com_w - pelvis_com_w, force)])


def test_pelvis_wrench_matches_mujoco_xfrc_applied(g1_pin, g1_mj_rigid, rng):
    model = g1_mj_rigid
    pelvis = model.body(g1.BASE_LINK).id
    for _ in range(5):
        q = g1_pin.q_stand.copy()
        q[g1_pin.joint_q_index] += rng.normal(0.0, 0.2, g1.NUM_JOINTS)
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
        wrench = rng.normal(0.0, 50.0, 6)
        data = mujoco.MjData(model)
        data.qpos[:] = pin_to_mj_qpos(q)
        mujoco.mj_forward(model, data)
        smooth_without = data.qfrc_smooth.copy()
        data.xfrc_applied[pelvis] = xfrc_applied_from_pelvis_wrench(wrench)
        mujoco.mj_forward(model, data)
        # MuJoCo adds the generalized force of xfrc_applied into qfrc_smooth.
        qfrc_mj = data.qfrc_smooth - smooth_without
        tau_pin = velocity_map_pin_to_mj(q).T @ qfrc_mj
        np.testing.assert_allclose(
            generalized_force_of_pelvis_wrench(g1_pin, q, wrench), tau_pin, atol=1e-9
        )
        # The point it acts at is the pelvis body CoM in both models.
        pin_data = g1_pin.data()
        pin.forwardKinematics(g1_pin.model, pin_data, q)
        np.testing.assert_allclose(
            pin_data.oMi[1].act(pelvis_com_offset_m(g1_pin)), data.xipos[pelvis], atol=1e-9
        )


def test_static_standing_needs_no_help(g1_pin):
    qp = WrenchQP()
    sol = qp.solve(g1_pin.q_stand, np.zeros(NV), np.zeros(NV), (True, True))
    assert sol.unaided
    assert np.linalg.norm(sol.wrench_w) < 0.05
    assert sol.residual < 1e-4
    # The soles carry the weight, each with its centre of pressure inside the sole.
    np.testing.assert_allclose(
        sol.contact_wrench_w[:, 2].sum(), g1_pin.total_mass_kg * GRAVITY, rtol=1e-4
    )
    assert np.all(sol.corner_forces_w[..., 2] >= -1e-6)
    assert np.all(np.abs(sol.tau_nm) <= g1.EFFORT_LIMIT_NM + 1e-6)


def test_no_contact_needs_exactly_the_weight(g1_pin):
    q = g1_pin.q_stand
    sol = WrenchQP().solve(q, np.zeros(NV), np.zeros(NV), (False, False))
    np.testing.assert_allclose(sol.wrench_w, _weight_wrench_at_pelvis_com(g1_pin, q), atol=1e-3)
    assert not sol.unaided
    np.testing.assert_allclose(sol.corner_forces_w, 0.0, atol=1e-6)
    assert sol.residual < 1e-4


def test_single_support_off_balance_needs_help_and_lifted_foot_carries_nothing(g1_pin):
    # Standing pose on the left sole only: the CoM is between the feet, outside the left sole.
    sol = WrenchQP().solve(g1_pin.q_stand, np.zeros(NV), np.zeros(NV), (True, False))
    assert not sol.unaided
    np.testing.assert_allclose(sol.corner_forces_w[1], 0.0, atol=1e-5)  # proxsuite eps_abs
    # The help is mostly a roll torque (the weight is carried by the left sole).
    assert abs(sol.wrench_w[3]) > abs(sol.wrench_w[2])


def _squat_pose(robot):
    """A deep squat on both soles, heavy on knees and hips."""
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


def test_lowering_alpha_never_lowers_the_wrench(g1_pin):
    q = _squat_pose(g1_pin)
    a = np.zeros(NV)
    a[2] = 3.0  # the pelvis accelerating up out of the squat, joints still
    qp = WrenchQP()
    norms = []
    for alpha in (1.0, 0.75, 0.5, 0.25, 0.1):
        sol = qp.solve(q, np.zeros(NV), a, (True, True), alpha=alpha)
        assert sol.solved and sol.residual < 1e-4
        assert np.all(np.abs(sol.tau_nm) <= alpha * g1.EFFORT_LIMIT_NM + 1e-5)
        norms.append(np.linalg.norm(sol.wrench_w))
    assert np.all(np.diff(norms) >= -1e-3), norms
    assert norms[-1] > norms[0] + 10.0  # the squat cannot be held without joint torque


def test_passive_joints_are_reported_infeasible(g1_pin):
    # Hard joint rows, alpha = 0: no pelvis wrench can hold the arms and legs: flagged.
    hard = WrenchQP(WrenchQPConfig(soft_joint_rows=False))
    sol = hard.solve(_squat_pose(g1_pin), np.zeros(NV), np.zeros(NV), (True, True), alpha=0)
    assert not sol.solved and not sol.unaided
    assert sol.residual > 1.0
    # The novice model (soft joint rows) answers: the limbs lag, the base rows hold exactly.
    sol = WrenchQP().solve(_squat_pose(g1_pin), np.zeros(NV), np.zeros(NV), (True, True), alpha=0)
    assert sol.solved and not sol.unaided and sol.residual < 1e-4
    assert np.abs(sol.missing_torque_nm).max() > 1.0


def test_sideways_acceleration_on_ice_is_flagged_with_the_expected_wrench(g1_pin):
    q = g1_pin.q_stand
    accel_y = 1.5  # [m/s^2] the whole robot translating sideways, rigidly (world = pelvis axes)
    a = np.zeros(NV)
    a[1] = accel_y
    ice = WrenchQP(WrenchQPConfig(friction_coefficient=0.0))
    sol = ice.solve(q, np.zeros(NV), a, (True, True))
    assert not sol.unaided
    mass = g1_pin.total_mass_kg
    data = g1_pin.data()
    com_w = pin.centerOfMass(g1_pin.model, data, q)
    dx = (data.oMi[1].act(pelvis_com_offset_m(g1_pin)) - com_w)[0]
    # Only w can push sideways or twist about z; the soles (vertical forces) do the rest.
    expected = np.array([0.0, mass * accel_y, 0.0, 0.0, 0.0, -dx * mass * accel_y])
    np.testing.assert_allclose(sol.wrench_w, expected, atol=2e-2)
    np.testing.assert_allclose(sol.corner_forces_w[..., :2], 0.0, atol=1e-6)
    # With friction the same motion needs no help.
    assert WrenchQP().solve(q, np.zeros(NV), a, (True, True)).unaided


def test_warm_start_gives_the_cold_answer(g1_pin, rng):
    ref = static_reference(_squat_pose(g1_pin), 12, 0.02)
    ref.a[:] = rng.normal(0.0, 1.0, ref.a.shape)
    ref.contacts[4:8, 1] = False
    cfg = WrenchQPConfig(alpha=0.5)
    warm = WrenchQP(cfg).solve_reference(ref)
    cold = WrenchQP(dataclasses.replace(cfg, warm_start=False)).solve_reference(ref)
    np.testing.assert_allclose(warm.wrench_w, cold.wrench_w, atol=1e-3)
    assert warm.residual.max() < 1e-4
    assert warm.solved.all()
    # Repeating a frame, the warm start is already the solution.
    still = static_reference(_squat_pose(g1_pin), 4, 0.02)
    warm_still = WrenchQP(cfg).solve_reference(still)
    assert np.all(warm_still.iterations[1:] == 0) and warm_still.warm_started[1:].all()
    assert not cold.warm_started.any()
    cold_still = WrenchQP(dataclasses.replace(cfg, warm_start=False)).solve_reference(still)
    assert np.all(cold_still.iterations > 0)
    assert warm.wrench_w.shape == (12, 6) and warm.tau_nm.shape == (12, g1.NUM_JOINTS)


def test_bad_config_is_rejected():
    with pytest.raises(ValueError, match="alpha"):
        WrenchQP(WrenchQPConfig(alpha=-0.1))
    assert NX == 88
