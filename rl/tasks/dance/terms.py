"""The dance's command layout, the step features it is made of, and its tracking reward terms.

Command (paper, "Dancing"): ``c_t = [dp_cmd (3), dq_cmd (4), q_cmd (29)]`` (width 36), the
reference's step for the *next* policy step: its base displacement over one step ``dt`` in its own
heading (yaw) frame, its base rotation over the step as a unit quaternion ``exp(w_b dt / 2)``
(w x y z, body frame), and its joint angles. The robot's own ``dp`` and ``dq`` are computed by the
same functions from its state (pelvis velocity x ``dt`` in its heading frame, pelvis rotation over
``dt``), so a robot put exactly on the reference frame has exactly zero tracking error.
"""

from __future__ import annotations

import torch

from rl.envs.state import EnvState, yaw_rad
from robots import g1

COMMAND_DIM = 3 + 4 + g1.NUM_JOINTS
"""Width of the dance command [dp (3), dq (4), q (29)]."""


# --------------------------------------------------------------------------- step features
def step_displacement(
    quat_wxyz: torch.Tensor, lin_vel_w: torch.Tensor, dt_s: float
) -> torch.Tensor:
    """Base displacement over one step ``dt_s`` [s] in the heading frame, (N, 3) [m]."""
    yaw = yaw_rad(quat_wxyz)
    c, s = torch.cos(yaw), torch.sin(yaw)
    d = lin_vel_w * dt_s
    return torch.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], dim=-1)


def step_rotation(ang_vel_b: torch.Tensor, dt_s: float) -> torch.Tensor:
    """Base rotation over one step as a unit quaternion exp(w dt / 2), (N, 4) w x y z [-]."""
    rot = ang_vel_b * dt_s
    angle = rot.norm(dim=-1, keepdim=True)
    half = angle / 2
    # sin(a/2)/a with its limit 1/2 at a = 0 (no division by zero)
    scale = torch.where(angle > 1e-8, torch.sin(half) / angle.clamp_min(1e-8), 0.5 - angle**2 / 48)
    return torch.cat([torch.cos(half), rot * scale], dim=-1)


def split_command(command: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The command's parts: ``dp_cmd`` (N, 3) [m], ``dq_cmd`` (N, 4) [-], ``q_cmd`` (N, 29) [rad]."""
    return command[:, :3], command[:, 3:7], command[:, 7:]


# ------------------------------------------------------------------------------- reward terms
def base_displacement_error_sq(s: EnvState) -> torch.Tensor:
    """``|dp - dp_cmd|^2`` (N,) [m^2]."""
    dp = step_displacement(s.base_quat_w, s.base_lin_vel_w, s.step_dt_s)
    return (dp - split_command(s.command)[0]).square().sum(-1)


def base_rotation_error_sq(s: EnvState) -> torch.Tensor:
    """``|dq - dq_cmd|^2`` of the step quaternions (N,) [-]."""
    dq = step_rotation(s.base_ang_vel_b, s.step_dt_s)
    return (dq - split_command(s.command)[1]).square().sum(-1)


def joint_error_sq(s: EnvState) -> torch.Tensor:
    """``|q - q_cmd|^2`` summed over the 29 joints (N,) [rad^2]."""
    return (s.joint_pos_rad - split_command(s.command)[2]).square().sum(-1)


def joint_error_mean_abs(s: EnvState) -> torch.Tensor:
    """Mean absolute joint tracking error over the 29 joints (N,) [rad] (the skill's error)."""
    return (s.joint_pos_rad - split_command(s.command)[2]).abs().mean(-1)


def track_base_position(s: EnvState, scale: float = 2500.0) -> torch.Tensor:
    """``exp(-scale |dp - dp_cmd|^2)`` (N,) [-] (``scale`` [1/m^2])."""
    return torch.exp(-scale * base_displacement_error_sq(s))


def track_base_rotation(s: EnvState, scale: float = 100.0) -> torch.Tensor:
    """``exp(-scale |dq - dq_cmd|^2)`` (N,) [-]."""
    return torch.exp(-scale * base_rotation_error_sq(s))


def track_joint_position(s: EnvState, scale: float = 0.25) -> torch.Tensor:
    """``exp(-scale |q - q_cmd|^2)`` (N,) [-] (``scale`` [1/rad^2])."""
    return torch.exp(-scale * joint_error_sq(s))


def track_joint_rms(s: EnvState, std_rad: float = 0.2) -> torch.Tensor:
    """``exp(-(rms / std)^2)`` of the RMS joint error over the 29 joints (N,) [-].

    Steep around the skill target: with ``std_rad`` 0.2 (an RMS of 0.2 rad is a mean absolute error
    of about 0.16 rad, the target) it pays 0.61 at 0.14 rad RMS, 0.37 at 0.2 and 0.04 at 0.36,
    where the paper's ``exp(-0.25 |e|^2)`` pays 0.87, 0.75 and 0.39 (it acts as an alive bonus).
    """
    mean_sq = joint_error_sq(s) / s.joint_pos_rad.shape[-1]
    return torch.exp(-mean_sq / std_rad**2)
