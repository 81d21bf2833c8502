"""Static standing: the joint torques that hold the G1 in a double-support pose.

A PD position hold at the G1 gains of :mod:`robots.g1` cannot by itself keep the robot upright: the
whole body pivoting about the ankles is an inverted pendulum of gravitational stiffness m g h
(about 33 kg * 9.81 * 0.67 m = 217 Nm/rad) while the two ankle-pitch PD springs give 2 * 28.5 =
57 Nm/rad. The standing keyframe is an equilibrium, but an unstable one: a policy (or a balance
controller) must stabilise it. :func:`hold_gain_scale` gives the gain multiplier that makes a pure
PD hold statically stable, used to check that the model itself stands without drifting.
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pinocchio as pin

from robots import g1
from robots.pinocchio_model import G1Pinocchio


def static_stand_torques_nm(robot: G1Pinocchio, q: np.ndarray) -> np.ndarray:
    """Joint torques (29,) [Nm] holding configuration q (36,) at rest on both soles.

    Gravity is balanced by two sole wrenches (least-norm split) and the joint torques; the result is
    exact for the floating-base statics. Returned in the order of :data:`robots.g1.JOINTS`.
    """
    data = robot.data()
    gravity = pin.computeGeneralizedGravity(robot.model, data, q)
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    jac = np.vstack(
        [
            pin.getFrameJacobian(robot.model, data, robot.frame_ids[name], pin.LOCAL_WORLD_ALIGNED)
            for name in g1.SOLE_FRAMES
        ]
    )
    wrench = np.linalg.lstsq(jac[:, :6].T, gravity[:6], rcond=None)[0]
    tau_v = gravity - jac.T @ wrench
    return tau_v[robot.joint_v_index]


def gravity_compensated_targets_rad(
    robot: G1Pinocchio, q: np.ndarray, kp: np.ndarray
) -> np.ndarray:
    """PD joint targets (29,) [rad] whose spring torque at q equals the static torque."""
    return q[robot.joint_q_index] + static_stand_torques_nm(robot, q) / kp


def hold_gain_scale(robot: G1Pinocchio, q: np.ndarray, margin: float = 2.0) -> float:
    """Multiplier of the table gains making the ankle springs ``margin`` times stiffer than m g h."""
    data = robot.data()
    com_z = pin.centerOfMass(robot.model, data, q)[2]
    pendulum_stiffness = robot.total_mass_kg * 9.81 * com_z
    ankle_stiffness = sum(j.motor.kp for j in g1.JOINTS if j.name.endswith("ankle_pitch_joint"))
    return max(1.0, margin * pendulum_stiffness / ankle_stiffness)


def with_scaled_gains(model: mujoco.MjModel, scale: float) -> mujoco.MjModel:
    """A copy of ``model`` whose position-actuator gains Kp and Kd are both scaled by ``scale``
    (damping grows with stiffness so the whole-body sway stays well damped)."""
    scaled = copy.deepcopy(model)
    scaled.actuator_gainprm[:, 0] *= scale
    scaled.actuator_biasprm[:, 1] *= scale
    scaled.actuator_biasprm[:, 2] *= scale
    return scaled
