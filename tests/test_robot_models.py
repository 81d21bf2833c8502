"""Pinocchio and MuJoCo describe the same G1: mass, CoM, kinematics, mass matrix, dynamics."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from robots import g1
from robots.assets import RobotAssetError, g1_description_dir
from robots.conventions import (
    mj_to_pin_q,
    mj_to_pin_v,
    pin_to_mj_qpos,
    pin_to_mj_qvel,
    velocity_map_pin_to_mj,
)

NUM_SAMPLES = 25


def random_state(robot, rng):
    """A random configuration inside the joint limits, velocity and acceleration (Pinocchio)."""
    lower, upper = robot.position_lower_rad, robot.position_upper_rad
    joints = lower + (upper - lower) * rng.uniform(0.05, 0.95, g1.NUM_JOINTS)
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    q = robot.configuration(joints, rng.normal(0.0, 0.5, 3) + [0, 0, 2.0], quat)
    v = rng.normal(0.0, 1.0, robot.model.nv)
    a = rng.normal(0.0, 2.0, robot.model.nv)
    return q, v, a


def mj_state(model, q, v=None):
    data = mujoco.MjData(model)
    data.qpos[:] = pin_to_mj_qpos(q)
    if v is not None:
        data.qvel[:] = pin_to_mj_qvel(q, v)
    mujoco.mj_forward(model, data)
    return data


def test_joint_order_is_the_same_everywhere(g1_pin, g1_mj):
    pin_names = [n for n in g1_pin.model.names if n not in ("universe", "root_joint")]
    mj_names = [g1_mj.joint(i).name for i in range(1, g1_mj.njnt)]
    actuator_names = [g1_mj.actuator(i).name for i in range(g1_mj.nu)]
    assert pin_names == list(g1.JOINT_NAMES)
    assert mj_names == list(g1.JOINT_NAMES)
    assert actuator_names == list(g1.JOINT_NAMES)
    # Each joint's qpos/qvel address matches its Pinocchio index (free joint first in both).
    for i, name in enumerate(g1.JOINT_NAMES):
        assert g1_mj.jnt_qposadr[g1_mj.joint(name).id] == g1_pin.joint_q_index[i]
        assert g1_mj.jnt_dofadr[g1_mj.joint(name).id] == g1_pin.joint_v_index[i]


def test_joint_limits_gains_and_effort_come_from_the_table(g1_pin, g1_mj):
    for i, joint in enumerate(g1.JOINTS):
        jid = g1_mj.joint(joint.name).id
        np.testing.assert_allclose(
            g1_mj.jnt_range[jid], [g1_pin.position_lower_rad[i], g1_pin.position_upper_rad[i]]
        )
        assert g1_mj.dof_armature[g1_mj.jnt_dofadr[jid]] == pytest.approx(joint.motor.armature)
        assert g1_mj.actuator_gainprm[i, 0] == pytest.approx(joint.motor.kp)
        assert g1_mj.actuator_biasprm[i, 2] == pytest.approx(-joint.motor.kd)
        assert g1_mj.actuator_forcerange[i, 1] == pytest.approx(joint.motor.effort_nm)


def test_total_mass(g1_pin, g1_mj):
    assert g1_pin.total_mass_kg == pytest.approx(33.34, abs=0.01)
    assert g1_mj.body_subtreemass[1] == pytest.approx(g1_pin.total_mass_kg, rel=1e-9)


def test_quaternion_and_velocity_conventions_round_trip(g1_pin, rng):
    for _ in range(5):
        q, v, _ = random_state(g1_pin, rng)
        np.testing.assert_allclose(mj_to_pin_q(pin_to_mj_qpos(q)), q)
        np.testing.assert_allclose(mj_to_pin_v(pin_to_mj_qpos(q), pin_to_mj_qvel(q, v)), v)
        np.testing.assert_allclose(velocity_map_pin_to_mj(q) @ v, pin_to_mj_qvel(q, v))


def test_velocity_conventions_integrate_identically(g1_pin, g1_mj_rigid, rng):
    """A small step of v in Pinocchio lands where the same step of qvel lands in MuJoCo."""
    dt = 1e-3
    for _ in range(5):
        q, v, _ = random_state(g1_pin, rng)
        q_next_pin = pin.integrate(g1_pin.model, q, v * dt)
        qpos = pin_to_mj_qpos(q)
        mujoco.mj_integratePos(g1_mj_rigid, qpos, pin_to_mj_qvel(q, v), dt)
        # Pinocchio integrates on SE(3), MuJoCo with R held: they differ at O(dt^2); a wrong
        # velocity frame would differ at O(dt |v|) ~ 1e-3.
        np.testing.assert_allclose(mj_to_pin_q(qpos)[:3], q_next_pin[:3], atol=1e-5)
        np.testing.assert_allclose(
            np.abs(np.dot(mj_to_pin_q(qpos)[3:7], q_next_pin[3:7])), 1.0, atol=1e-9
        )
        np.testing.assert_allclose(mj_to_pin_q(qpos)[7:], q_next_pin[7:], atol=1e-12)


def test_centre_of_mass_and_frame_kinematics_agree(g1_pin, g1_mj_rigid, rng):
    data = g1_pin.data()
    for _ in range(NUM_SAMPLES):
        q, _, _ = random_state(g1_pin, rng)
        mj = mj_state(g1_mj_rigid, q)
        np.testing.assert_allclose(
            pin.centerOfMass(g1_pin.model, data, q), mj.subtree_com[1], atol=1e-10
        )
        pin.framesForwardKinematics(g1_pin.model, data, q)
        for frame in g1.FRAMES:
            placement = data.oMf[g1_pin.frame_ids[frame.name]]
            site = g1_mj_rigid.site(frame.name).id
            np.testing.assert_allclose(placement.translation, mj.site_xpos[site], atol=1e-10)
            np.testing.assert_allclose(
                placement.rotation, mj.site_xmat[site].reshape(3, 3), atol=1e-10
            )


def test_mass_matrix_agrees(g1_pin, g1_mj_rigid, rng):
    data = g1_pin.data()
    for _ in range(NUM_SAMPLES):
        q, _, _ = random_state(g1_pin, rng)
        mj = mj_state(g1_mj_rigid, q)
        mass_mj = np.zeros((g1_mj_rigid.nv, g1_mj_rigid.nv))
        mujoco.mj_fullM(g1_mj_rigid, mj, mass_mj)
        t = velocity_map_pin_to_mj(q)
        mass_pin = pin.crba(g1_pin.model, data, q)
        mass_pin = np.triu(mass_pin) + np.triu(mass_pin, 1).T
        np.testing.assert_allclose(t.T @ mass_mj @ t, mass_pin, atol=1e-9)


def test_inverse_dynamics_and_bias_agree(g1_pin, g1_mj_rigid, rng):
    """pin.rnea(q, v, a) equals MuJoCo's mj_inverse mapped to Pinocchio coordinates."""
    data = g1_pin.data()
    for _ in range(NUM_SAMPLES):
        q, v, a = random_state(g1_pin, rng)
        mj = mj_state(g1_mj_rigid, q, v)
        t = velocity_map_pin_to_mj(q)
        # qacc_mj = d/dt (T v) = T a + [R (omega_b x v_b); 0]
        qacc = t @ a
        qacc[:3] += t[:3, :3] @ np.cross(v[3:6], v[:3])
        mj.qacc[:] = qacc
        mujoco.mj_inverse(g1_mj_rigid, mj)
        np.testing.assert_allclose(
            t.T @ mj.qfrc_inverse, pin.rnea(g1_pin.model, data, q, v, a), atol=1e-8
        )
        # The bias (gravity + Coriolis) alone: qacc_mj = 0 is a_pin = [-(omega_b x v_b), 0].
        a_zero_mj = np.zeros_like(a)
        a_zero_mj[:3] = -np.cross(v[3:6], v[:3])
        np.testing.assert_allclose(
            t.T @ mj.qfrc_bias,
            pin.rnea(g1_pin.model, data, q, v, a_zero_mj),
            atol=1e-8,
        )


def test_standing_keyframe_is_the_pinocchio_stand_pose(g1_pin, g1_mj):
    """MuJoCo computes the standing pose itself (no Pinocchio at run time): the same q_stand."""
    from robots.mujoco_model import STAND_KEYFRAME

    key_qpos = g1_mj.key(STAND_KEYFRAME).qpos
    np.testing.assert_allclose(key_qpos, pin_to_mj_qpos(g1_pin.q_stand), rtol=0, atol=1e-12)
    data = mujoco.MjData(g1_mj)
    mujoco.mj_resetDataKeyframe(g1_mj, data, g1_mj.key(STAND_KEYFRAME).id)
    mujoco.mj_kinematics(g1_mj, data)
    assert min(data.site(name).xpos[2] for name in g1.SOLE_FRAMES) == pytest.approx(0, abs=1e-12)


def test_sole_corner_heights_of_mujoco_are_pinocchios(g1_pin, rng):
    """The motion library's floor shift reads MuJoCo's sole-corner heights (no Pinocchio on the
    GPU machine): the same as Pinocchio's, at the stand and at random poses."""
    from optimal_control.motion_clip import sole_corner_heights_m
    from robots.mujoco_model import sole_corner_heights_mj

    q = np.stack([g1_pin.q_stand] + [random_state(g1_pin, rng)[0] for _ in range(5)])
    heights_pin, _ = sole_corner_heights_m(q, g1_pin)
    np.testing.assert_allclose(sole_corner_heights_mj(pin_to_mj_qpos(q)), heights_pin, atol=1e-10)


def test_missing_description_gives_an_actionable_error(monkeypatch, tmp_path):
    monkeypatch.setenv("A2CF_G1_DESCRIPTION_DIR", str(tmp_path))
    with pytest.raises(RobotAssetError, match="A2CF_G1_DESCRIPTION_DIR"):
        g1_description_dir()


def test_every_urdf_visual_is_rendered_and_soles_collide(g1_mj):
    from robots.assets import g1_urdf_path

    visual_geoms = [i for i in range(g1_mj.ngeom) if g1_mj.geom_group[i] == 1]
    assert len(visual_geoms) == g1_urdf_path().read_text().count("<visual>")
    assert all(g1_mj.geom_contype[i] == 0 for i in visual_geoms)
    for side in g1.SOLE_FRAMES:
        for i in range(4):
            assert g1_mj.geom_contype[g1_mj.geom(f"{side}_{i}").id] == 1
