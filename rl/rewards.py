"""Reward terms: small pure functions over batched tensors, each returning shape (N,).

Tasks weight them (:class:`rl.tasks.RewardTerm`); the env multiplies by the policy step dt and logs
each weighted term as ``Reward/<name>``. Penalties return positive magnitudes and take negative
weights. No term reads or writes env state.
"""

from __future__ import annotations

import torch


def alive(base_pos_w: torch.Tensor) -> torch.Tensor:
    """1 for every env (N,); the base position (N, 3) only supplies the batch."""
    return torch.ones(base_pos_w.shape[0], dtype=base_pos_w.dtype, device=base_pos_w.device)


def upright(projected_gravity_b: torch.Tensor, std: float = 0.25) -> torch.Tensor:
    """exp(-|g_xy|^2 / std^2) of the gravity direction in the pelvis frame (N, 3): 1 when upright."""
    return torch.exp(-projected_gravity_b[:, :2].square().sum(-1) / std**2)


def base_height(base_height_m: torch.Tensor, target_m: float, std_m: float = 0.1) -> torch.Tensor:
    """exp(-(h - target)^2 / std^2) of the pelvis height (N,) [m]."""
    return torch.exp(-(base_height_m - target_m).square() / std_m**2)


def joint_deviation_l2(joint_pos_rad: torch.Tensor, default_rad: torch.Tensor) -> torch.Tensor:
    """Sum of squared joint offsets (N, 29) from a default pose (29,) [rad^2]."""
    return (joint_pos_rad - default_rad).square().sum(-1)


def action_rate_l2(action: torch.Tensor, last_action: torch.Tensor) -> torch.Tensor:
    """Sum of squared action changes between two policy steps (N, A)."""
    return (action - last_action).square().sum(-1)


def torques_l2(joint_torque_nm: torch.Tensor) -> torch.Tensor:
    """Sum of squared joint torques (N, 29) [Nm^2]."""
    return joint_torque_nm.square().sum(-1)


def joint_vel_l2(joint_vel_rps: torch.Tensor) -> torch.Tensor:
    """Sum of squared joint rates (N, 29) [rad^2/s^2]."""
    return joint_vel_rps.square().sum(-1)


def base_lin_vel_xy_l2(base_lin_vel_b: torch.Tensor) -> torch.Tensor:
    """Squared horizontal pelvis speed (N, 3) in the pelvis frame [m^2/s^2]."""
    return base_lin_vel_b[:, :2].square().sum(-1)


def base_ang_vel_xy_l2(base_ang_vel_b: torch.Tensor) -> torch.Tensor:
    """Squared roll / pitch rate of the pelvis (N, 3) [rad^2/s^2]."""
    return base_ang_vel_b[:, :2].square().sum(-1)


def feet_contact(foot_contact_force_n: torch.Tensor, threshold_n: float = 1.0) -> torch.Tensor:
    """Fraction of the feet (N, 2) pressing the ground with more than ``threshold_n`` [N]."""
    return (foot_contact_force_n > threshold_n).to(foot_contact_force_n.dtype).mean(-1)


def termination(terminated: torch.Tensor) -> torch.Tensor:
    """1 for envs (N,) that failed this step (not time-outs), else 0; weight it negatively."""
    return terminated.to(torch.float32)


def less_assist(applied_wrench: torch.Tensor, bound: torch.Tensor) -> torch.Tensor:
    """A2CF less-assist reward exp(-2 |F| / |eta|) of the applied wrench (N, 6) and its bound (N, 6).

    1 without help; an env whose bound is zero (no help possible) gets 1.
    """
    force_norm = applied_wrench.norm(dim=-1)
    bound_norm = bound.norm(dim=-1)
    ratio = torch.where(
        bound_norm > 0, force_norm / bound_norm.clamp_min(1e-9), torch.zeros_like(force_norm)
    )
    return torch.exp(-2.0 * ratio)
