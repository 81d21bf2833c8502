"""Reward terms: small pure functions of the batched :class:`EnvState`, each returning shape (N,).

A task lists them as :class:`rl.envs.terms.RewardTerm` (name, function, weight, parameters); the
env multiplies each by its weight and the policy step dt and logs it as ``Reward/<name>``.
Penalties return positive magnitudes and take negative weights. No term reads or writes env state
beyond its argument.
"""

from __future__ import annotations

import functools

import torch

from rl.envs.state import EnvState
from robots import g1


def alive(s: EnvState) -> torch.Tensor:
    """1 for every env (N,)."""
    return torch.ones(s.base_pos_w.shape[0], dtype=s.base_pos_w.dtype, device=s.base_pos_w.device)


def upright(s: EnvState, std: float = 0.25) -> torch.Tensor:
    """exp(-|g_xy|^2 / std^2) of the gravity direction in the pelvis frame: 1 when upright."""
    return torch.exp(-s.projected_gravity_b[:, :2].square().sum(-1) / std**2)


def base_height(s: EnvState, target_m: float, std_m: float = 0.1) -> torch.Tensor:
    """exp(-(h - target)^2 / std^2) of the pelvis height h [m]."""
    return torch.exp(-(s.base_pos_w[:, 2] - target_m).square() / std_m**2)


def joint_deviation_l2(s: EnvState) -> torch.Tensor:
    """Sum of squared joint offsets from the default pose [rad^2]."""
    return (s.joint_pos_rad - s.default_joint_pos_rad).square().sum(-1)


def joint_deviation_named_l2(s: EnvState, joints: tuple[str, ...]) -> torch.Tensor:
    """Sum of squared offsets from the default pose of the named joints [rad^2] (pose terms that
    hold, e.g., the waist and arms while the legs walk)."""
    idx = _joint_indices(joints)
    return (s.joint_pos_rad[:, idx] - s.default_joint_pos_rad[idx]).square().sum(-1)


@functools.lru_cache(maxsize=32)
def _joint_indices(joints: tuple[str, ...]) -> list[int]:
    unknown = [j for j in joints if j not in g1.JOINT_NAMES]
    if unknown:
        raise ValueError(f"unknown G1 joints {unknown}; joints: {list(g1.JOINT_NAMES)}")
    return [g1.JOINT_NAMES.index(j) for j in joints]


def action_rate_l2(s: EnvState) -> torch.Tensor:
    """Sum of squared motion-action changes between two policy steps [-]."""
    return (s.action - s.last_action).square().sum(-1)


def torques_l2(s: EnvState) -> torch.Tensor:
    """Sum of squared joint torques [Nm^2]."""
    return s.joint_torque_nm.square().sum(-1)


def joint_vel_l2(s: EnvState) -> torch.Tensor:
    """Sum of squared joint rates [rad^2/s^2]."""
    return s.joint_vel_rps.square().sum(-1)


def base_lin_vel_xy_l2(s: EnvState) -> torch.Tensor:
    """Squared horizontal pelvis speed in the pelvis frame [m^2/s^2]."""
    return s.base_lin_vel_b[:, :2].square().sum(-1)


def base_ang_vel_xy_l2(s: EnvState) -> torch.Tensor:
    """Squared roll / pitch rate of the pelvis [rad^2/s^2]."""
    return s.base_ang_vel_b[:, :2].square().sum(-1)


def feet_contact(s: EnvState, threshold_n: float = 1.0) -> torch.Tensor:
    """Fraction of the two feet pressing the ground with more than ``threshold_n`` [N]."""
    force = s.foot_contact_force_n
    return (force > threshold_n).to(force.dtype).mean(-1)


def joint_acc_l2(s: EnvState) -> torch.Tensor:
    """Sum of squared joint accelerations over the last policy step [rad^2/s^4]."""
    return s.joint_acc_rps2.square().sum(-1)


def joint_pos_limits(s: EnvState, soft_ratio: float = 1.0) -> torch.Tensor:
    """Sum over joints of how far each is beyond its (soft) position limits [rad].

    ``soft_ratio`` < 1 shrinks the range about its middle (0.9: the outer 5 % on each side count).
    """
    low, high = s.joint_pos_limits_rad[:, 0], s.joint_pos_limits_rad[:, 1]
    mid, half = (low + high) / 2, (high - low) / 2 * soft_ratio
    q = s.joint_pos_rad
    return ((mid - half - q).clamp_min(0) + (q - mid - half).clamp_min(0)).sum(-1)


def orientation_l2(s: EnvState) -> torch.Tensor:
    """Squared horizontal part of the gravity direction in the pelvis frame (0 upright) [-]."""
    return s.projected_gravity_b[:, :2].square().sum(-1)


def ang_vel_z_l2(s: EnvState) -> torch.Tensor:
    """Squared yaw rate of the pelvis [rad^2/s^2]."""
    return s.base_ang_vel_b[:, 2].square()


def feet_slide(s: EnvState, threshold_n: float = 1.0) -> torch.Tensor:
    """Horizontal speed of the feet that are on the ground, summed over the two feet [m/s]."""
    on_ground = (s.foot_contact_force_n > threshold_n).to(s.foot_vel_w.dtype)
    return (s.foot_vel_w[..., :2].norm(dim=-1) * on_ground).sum(-1)


def link_ground_contact(s: EnvState, bodies: tuple[str, ...] = ()) -> torch.Tensor:
    """Number of the named links (all non-foot links when empty) touching the ground [-]."""
    return _contacts(s, bodies).sum(-1).to(torch.float32)


class MissingContactSensorError(ValueError):
    """A term names links that have no ground-contact sensor in this scene (e.g. link collision
    primitives switched off)."""


def _contacts(s: EnvState, bodies: tuple[str, ...]) -> torch.Tensor:
    if not bodies:
        return s.body_ground_contact
    names = s.contact_body_names
    missing = [b for b in bodies if b not in names]
    if missing:
        raise MissingContactSensorError(
            f"no ground-contact sensor for {missing}; bodies with one: {names}"
        )
    return s.body_ground_contact[:, [names.index(b) for b in bodies]]


def termination(s: EnvState) -> torch.Tensor:
    """1 for envs that failed this step (not time-outs), else 0; weight it negatively."""
    return s.terminated.to(torch.float32)
