"""The MuJoCo G1 is physically sound: it stands under a PD hold and falls without exploding."""

from __future__ import annotations

import mujoco
import numpy as np

from robots import g1, stand_data
from robots.conventions import quat_wxyz_to_matrix
from robots.standing import (
    gravity_compensated_targets_rad,
    hold_gain_scale,
    static_stand_torques_nm,
    with_scaled_gains,
)

TEN_SECONDS = 2000  # physics steps at dt 0.005


def tilt_deg(qpos):
    return np.degrees(np.arccos(np.clip(quat_wxyz_to_matrix(qpos[3:7])[2, 2], -1, 1)))


def test_static_torques_balance_gravity(g1_pin):
    tau = static_stand_torques_nm(g1_pin, g1_pin.q_stand)
    assert tau.shape == (g1.NUM_JOINTS,)
    assert np.all(np.abs(tau) < g1.EFFORT_LIMIT_NM)
    # Symmetric pose (the URDF is symmetric to ~1e-4): the knees carry the same load.
    knees = [g1.JOINT_NAMES.index(f"{side}_knee_joint") for side in ("left", "right")]
    assert abs(tau[knees[0]] - tau[knees[1]]) < 1e-2
    assert abs(tau[knees[0]]) > 5.0


def test_stands_ten_seconds_under_pd_hold(g1_pin, g1_mj):
    scale = hold_gain_scale(g1_pin, g1_pin.q_stand)
    model = with_scaled_gains(g1_mj, scale)
    data = stand_data(model)
    data.ctrl[:] = gravity_compensated_targets_rad(g1_pin, g1_pin.q_stand, g1.KP * scale)
    start = data.qpos.copy()
    for _ in range(TEN_SECONDS // 2):
        mujoco.mj_step(model, data)
    settled = data.qpos.copy()
    for _ in range(TEN_SECONDS // 2):
        mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos))
    # Settling from the keyframe: the real contact pressure differs slightly from the static split.
    assert np.linalg.norm(data.qpos[:3] - start[:3]) < 0.02  # [m]
    assert tilt_deg(data.qpos) < 1.5
    # No drift over the last 5 s, and at rest.
    assert np.linalg.norm(data.qpos[:3] - settled[:3]) < 1e-3  # [m]
    assert np.abs(data.qpos[7:] - settled[7:]).max() < 1e-3  # [rad]
    assert np.abs(data.qvel).max() < 1e-2
    sole_geoms = {model.geom(f"{s}_{i}").id for s in g1.SOLE_FRAMES for i in range(4)}
    touching = {int(g) for c in data.contact[: data.ncon] for g in (c.geom1, c.geom2)}
    assert sole_geoms <= touching


def test_table_gains_cannot_hold_the_pose_alone_but_stay_physical(g1_pin, g1_mj):
    """With the deployment gains the stand pose is an unstable equilibrium: the robot falls,
    lands on the floor (link meshes collide with it) and nothing explodes."""
    assert hold_gain_scale(g1_pin, g1_pin.q_stand) > 1.0
    data = stand_data(g1_mj)
    data.ctrl[:] = gravity_compensated_targets_rad(g1_pin, g1_pin.q_stand, g1.KP)
    for _ in range(TEN_SECONDS):
        mujoco.mj_step(g1_mj, data)
    assert np.all(np.isfinite(data.qpos))
    assert np.abs(data.qvel).max() < 5.0  # came to rest on the ground
    assert 0.0 < data.qpos[2] < 0.5  # lying on the floor, not through it
    assert tilt_deg(data.qpos) > 45.0
