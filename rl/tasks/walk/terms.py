"""Walk-specific terms: velocity tracking, feet air time, cost of transport, stand still, and the
height scan observation. Pure functions of the batched :class:`EnvState`; reward terms return (N,).

The command is ``s.command`` (N, 3) or (N, 5): forward and lateral velocity in the pelvis frame
[m/s], yaw rate [rad/s] and, with a gait clock, sin and cos of the clock's phase
(:class:`rl.tasks.walk.command.VelocityCommandConfig`).
"""

from __future__ import annotations

from functools import lru_cache

import torch

from rl.envs.state import EnvState
from rl.tasks.terrain import HeightMap, Terrain

GRAVITY_MPS2 = 9.81


def moving(s: EnvState, min_command: float = 0.1) -> torch.Tensor:
    """(N,) bool: the velocity command (vx, vy, yaw rate) has a norm above ``min_command``."""
    return s.command[:, :3].norm(dim=-1) > min_command


def gait_phase(s: EnvState) -> torch.Tensor:
    """(N, 2) phase in [0, 1) of the left and right foot's gait cycle, read from the clock columns
    of the command (sin, cos of the left foot's phase); the right foot is half a cycle later."""
    left = torch.atan2(s.command[:, 3], s.command[:, 4]) / (2 * torch.pi) % 1.0
    return torch.stack([left, (left + 0.5) % 1.0], dim=-1)


def gait_contact(
    s: EnvState, stance_fraction: float = 0.55, threshold_n: float = 1.0, min_command: float = 0.1
) -> torch.Tensor:
    """Number of feet (0-2) whose ground contact matches the gait clock: a foot in the first
    ``stance_fraction`` of its cycle should be down, in the rest up; under a standing command
    both feet should be down (unitree_rl_gym's contact reward, standing case added)."""
    stance = gait_phase(s) < stance_fraction
    stance = stance | ~moving(s, min_command)[:, None]
    contact = s.foot_contact_force_n > threshold_n
    return (contact == stance).to(s.foot_contact_force_n.dtype).sum(-1)


def feet_swing_height(
    s: EnvState, target_m: float = 0.08, threshold_n: float = 1.0
) -> torch.Tensor:
    """Sum over the feet in the air of (sole height - ``target_m``)^2 [m^2] (flat ground)."""
    airborne = (s.foot_contact_force_n <= threshold_n).to(s.foot_pos_w.dtype)
    return ((s.foot_pos_w[..., 2] - target_m).square() * airborne).sum(-1)


def energy_per_weight(
    s: EnvState, min_speed_mps: float = 0.2, min_command: float = 0.1
) -> torch.Tensor:
    """Positive mechanical power over weight x commanded speed (a cost of transport), paid only
    under moving commands: sum_j max(tau_j qdot_j, 0) / (m g max(|v_cmd|, min_speed)) [-]."""
    power_w = (s.joint_torque_nm * s.joint_vel_rps).clamp_min(0.0).sum(-1)
    speed = s.command[:, :2].norm(dim=-1).clamp_min(min_speed_mps)
    return power_w / (s.weight_n * speed) * moving(s, min_command).to(power_w.dtype)


def lin_vel_z_l2(s: EnvState) -> torch.Tensor:
    """Squared vertical pelvis speed in the pelvis frame [m^2/s^2]."""
    return s.base_lin_vel_b[:, 2].square()


def track_lin_vel_xy_exp(s: EnvState, sharpness: float = 4.0) -> torch.Tensor:
    """exp(-sharpness |v_xy - v_xy^cmd|^2) of the pelvis-frame horizontal velocity [-]."""
    error = (s.base_lin_vel_b[:, :2] - s.command[:, :2]).square().sum(-1)
    return torch.exp(-sharpness * error)


def track_ang_vel_z_exp(s: EnvState, sharpness: float = 4.0) -> torch.Tensor:
    """exp(-sharpness (w_z - w_z^cmd)^2) of the pelvis yaw rate [-]."""
    error = (s.base_ang_vel_b[:, 2] - s.command[:, 2]).square()
    return torch.exp(-sharpness * error)


def feet_air_time(s: EnvState, min_command: float = 0.1) -> torch.Tensor:
    """sum_i 1_i t_air,i [s]: at the step foot i touches down, the duration of the swing it ended.

    Paid only while the command norm exceeds ``min_command`` (no reward for stepping when asked
    to stand; legged_gym's reading of the paper's term, without its 0.5 s offset).
    """
    landed = s.foot_first_contact.to(s.foot_last_air_time_s.dtype)
    reward = (landed * s.foot_last_air_time_s).sum(-1)
    return reward * moving(s, min_command).to(reward.dtype)


def cost_of_transport(s: EnvState, min_speed_mps: float = 0.1) -> torch.Tensor:
    """|qdot| |tau| / (9.81 max(|v_xy|, min_speed)) (the paper's form) [rad N m s^-1 / (m s^-2 m/s)].

    The speed is floored at ``min_speed_mps`` so standing still gives a finite cost.
    """
    speed = s.base_lin_vel_w[:, :2].norm(dim=-1).clamp_min(min_speed_mps)
    power = s.joint_vel_rps.norm(dim=-1) * s.joint_torque_nm.norm(dim=-1)
    return power / (GRAVITY_MPS2 * speed)


def stand_still(s: EnvState, max_command: float = 0.1) -> torch.Tensor:
    """1[|c| < max_command] |q - q_default| [rad]: hold the default pose when asked to stand."""
    standing = (~moving(s, max_command)).to(s.joint_pos_rad.dtype)
    return standing * (s.joint_pos_rad - s.default_joint_pos_rad).norm(dim=-1)


@lru_cache(maxsize=8)
def scan_offsets_b(
    size_m: tuple[float, float], resolution_m: float, device: torch.device | str = "cpu"
) -> torch.Tensor:
    """Grid points (P, 2) [m] of a ``size_m`` = (length x, width y) scan centred on the pelvis,
    on ``device`` (cached per size and device: treat the result as read-only)."""
    nx = int(round(size_m[0] / resolution_m)) + 1
    ny = int(round(size_m[1] / resolution_m)) + 1
    xs = torch.linspace(-size_m[0] / 2, size_m[0] / 2, nx, device=device)
    ys = torch.linspace(-size_m[1] / 2, size_m[1] / 2, ny, device=device)
    gx, gy = torch.meshgrid(xs, ys, indexing="ij")
    return torch.stack([gx.flatten(), gy.flatten()], dim=-1)


def height_scan(
    s: EnvState,
    terrain: Terrain | HeightMap,
    size_m: tuple[float, float] = (1.6, 1.0),
    resolution_m: float = 0.1,
    offset_m: float = 0.5,
    clip_m: float = 1.0,
) -> torch.Tensor:
    """Pelvis height above the terrain at a yaw-aligned grid around the pelvis (N, P) [m].

    Value = pelvis z - terrain height - ``offset_m``, clipped to +- ``clip_m`` (Isaac Lab's
    height-scan convention); P = (size_x / res + 1) (size_y / res + 1), row-major in x. Looked up
    in the terrain's height map for all envs at once.
    """
    height_map = terrain.height_map if isinstance(terrain, Terrain) else terrain
    offsets = scan_offsets_b(tuple(size_m), resolution_m, s.base_pos_w.device)  # (P, 2)
    q = s.base_quat_w
    # Heading of the pelvis x axis projected on the ground.
    yaw = torch.atan2(
        2 * (q[:, 0] * q[:, 3] + q[:, 1] * q[:, 2]), 1 - 2 * (q[:, 2] ** 2 + q[:, 3] ** 2)
    )
    cos, sin = torch.cos(yaw)[:, None], torch.sin(yaw)[:, None]
    x = s.base_pos_w[:, :1] + cos * offsets[:, 0] - sin * offsets[:, 1]
    y = s.base_pos_w[:, 1:2] + sin * offsets[:, 0] + cos * offsets[:, 1]
    ground = height_map(torch.stack([x, y], dim=-1))  # (N, P)
    return (s.base_pos_w[:, 2:3] - ground - offset_m).clamp(-clip_m, clip_m)
