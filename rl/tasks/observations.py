"""Observation terms: pure functions of the batched :class:`EnvState`, each returning (N, D).

Tasks list them per observation group as :class:`rl.envs.terms.ObsTerm` (name, function, scale,
noise); the env concatenates a group's terms in order. Nothing here knows column offsets.
"""

from __future__ import annotations

import torch

from rl.envs.state import EnvState, quat_rotate_inverse


def base_ang_vel_b(s: EnvState) -> torch.Tensor:
    """Pelvis angular velocity in the pelvis frame (N, 3) [rad/s] (the IMU gyro)."""
    return s.base_ang_vel_b


def projected_gravity_b(s: EnvState) -> torch.Tensor:
    """Unit gravity direction in the pelvis frame (N, 3) [-]."""
    return s.projected_gravity_b


def joint_pos_rel_rad(s: EnvState) -> torch.Tensor:
    """Joint angles relative to the default pose (N, 29) [rad]."""
    return s.joint_pos_rad - s.default_joint_pos_rad


def joint_vel_rps(s: EnvState) -> torch.Tensor:
    """Joint rates (N, 29) [rad/s]."""
    return s.joint_vel_rps


def last_action(s: EnvState) -> torch.Tensor:
    """Motion action of the previous policy step (N, 29) [-] (after a step: the one just applied)."""
    return s.last_action


def command(s: EnvState) -> torch.Tensor:
    """The task's command (N, C); (N, 0) for tasks without one."""
    return s.command


def base_lin_vel_b(s: EnvState) -> torch.Tensor:
    """Pelvis linear velocity in the pelvis frame (N, 3) [m/s] (privileged: no sensor gives it)."""
    return s.base_lin_vel_b


def assist_bound(s: EnvState) -> torch.Tensor:
    """The current wrench bound eta of each env's phase (N, 6) [N, Nm]."""
    return s.assist_bound


def randomization_params(s: EnvState) -> torch.Tensor:
    """Domain parameters (N, 5): friction, payload [kg], CoM offset xyz [m]."""
    return s.randomization_params


def phase_one_hot(s: EnvState) -> torch.Tensor:
    """One-hot task phase (N, P)."""
    return torch.nn.functional.one_hot(s.phase, s.num_phases).float()


def foot_contact_force_rel(s: EnvState) -> torch.Tensor:
    """Sole normal forces over the robot weight (N, 2) [-]."""
    return s.foot_contact_force_n / s.weight_n


def base_height_m(s: EnvState) -> torch.Tensor:
    """Pelvis height above the world origin (N, 1) [m]."""
    return s.base_pos_w[:, 2:3]


def feet_pos_b(s: EnvState) -> torch.Tensor:
    """Left then right sole centre relative to the pelvis, pelvis frame (N, 6) [m]."""
    return torch.cat(
        [quat_rotate_inverse(s.base_quat_w, s.foot_pos_w[:, k] - s.base_pos_w) for k in (0, 1)],
        dim=-1,
    )


def applied_wrench_rel(s: EnvState) -> torch.Tensor:
    """Pelvis wrench applied this step over the robot weight (N, 6) [1/m for the torque part]."""
    return s.applied_wrench / s.weight_n


def joint_torque_rel(s: EnvState) -> torch.Tensor:
    """Actuator torques over their effort limits (N, 29) [-]."""
    return s.joint_torque_nm / s.effort_limit_nm
