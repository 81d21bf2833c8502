"""The per-step robot state handed to tasks and reward terms, as batched torch tensors."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import torch


def quat_rotate_inverse(quat_wxyz: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Rotate world vectors (N, 3) into the frames of unit quaternions (N, 4) (w, x, y, z): R^T v."""
    w = quat_wxyz[:, :1]
    xyz = quat_wxyz[:, 1:]
    t = 2.0 * torch.cross(xyz, vec, dim=-1)
    return vec - w * t + torch.cross(xyz, t, dim=-1)


def quat_rotate(quat_wxyz: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """Rotate vectors (N, 3) from the frames of unit quaternions (N, 4) (w, x, y, z) to world: R v."""
    w = quat_wxyz[:, :1]
    xyz = quat_wxyz[:, 1:]
    t = 2.0 * torch.cross(xyz, vec, dim=-1)
    return vec + w * t + torch.cross(xyz, t, dim=-1)


def quat_multiply(a_wxyz: torch.Tensor, b_wxyz: torch.Tensor) -> torch.Tensor:
    """Hamilton products a * b of quaternion batches (N, 4) in w, x, y, z order."""
    aw, ax, ay, az = a_wxyz.unbind(-1)
    bw, bx, by, bz = b_wxyz.unbind(-1)
    return torch.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        dim=-1,
    )


def heading_to_world(wrench_h: torch.Tensor, quat_wxyz: torch.Tensor) -> torch.Tensor:
    """Rotate wrenches (N, 6) from each robot's heading frame (x forward along the pelvis yaw,
    z up) to the world frame, for ``xfrc_applied``: the assist wrench's frame and why it is that
    one are stated in :class:`rl.envs.assist_action.AssistAction`."""
    return _rotate_yaw(wrench_h, yaw_rad(quat_wxyz))


def world_to_heading(wrench_w: torch.Tensor, quat_wxyz: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`heading_to_world`: world-frame wrenches (N, 6) in the heading frame."""
    return _rotate_yaw(wrench_w, -yaw_rad(quat_wxyz))


def yaw_rad(quat_wxyz: torch.Tensor) -> torch.Tensor:
    """Heading (yaw about world z) of quaternions (N, 4) w x y z [rad]."""
    w, x, y, z = quat_wxyz.unbind(-1)
    return torch.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def _rotate_yaw(wrench_h: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(yaw), torch.sin(yaw)
    out = wrench_h.clone()
    for k in (0, 3):  # force, then torque: rotate the horizontal components
        out[:, k] = c * wrench_h[:, k] - s * wrench_h[:, k + 1]
        out[:, k + 1] = s * wrench_h[:, k] + c * wrench_h[:, k + 1]
    return out


FOOT_CONTACT_THRESHOLD_N = 1.0
"""Sole normal force above which a foot counts as on the ground (air/contact timers) [N]."""


@dataclass
class EnvState:
    """Robot and env state after a policy step, float32 tensors with a leading env axis N.

    Built once per step by :class:`rl.envs.G1VecEnv`; tasks and reward terms only read it.
    """

    base_pos_w: torch.Tensor  # (N, 3) pelvis position [m]
    base_quat_w: torch.Tensor  # (N, 4) pelvis orientation, w x y z
    base_lin_vel_w: torch.Tensor  # (N, 3) pelvis linear velocity, world frame [m/s]
    base_lin_vel_b: torch.Tensor  # (N, 3) pelvis linear velocity, pelvis frame [m/s]
    base_ang_vel_b: torch.Tensor  # (N, 3) pelvis angular velocity, pelvis frame [rad/s]
    projected_gravity_b: torch.Tensor  # (N, 3) unit gravity direction in the pelvis frame [-]
    joint_pos_rad: torch.Tensor  # (N, 29) joint angles [rad]
    joint_vel_rps: torch.Tensor  # (N, 29) joint rates [rad/s]
    joint_torque_nm: torch.Tensor  # (N, 29) actuator torques of the last physics step [Nm]
    foot_contact_force_n: torch.Tensor  # (N, 2) left / right sole normal force [N]
    foot_pos_w: torch.Tensor  # (N, 2, 3) left / right sole centre position [m]
    action: torch.Tensor  # (N, 29) motion action of this step [-]
    last_action: torch.Tensor  # (N, 29) motion action of the previous step [-]
    applied_wrench: torch.Tensor  # (N, 6) assist wrench of this step, heading frame [N, Nm]
    assist_bound: torch.Tensor  # (N, 6) eta of each env's phase [N, Nm]
    episode_time_s: torch.Tensor  # (N,) time since the env's last reset [s]
    command: torch.Tensor  # (N, C) the task's command (C = 0 without one)
    phase: torch.Tensor  # (N,) long, task phase of each env
    num_phases: int  # number of task phases P [-]
    randomization_params: torch.Tensor  # (N, 5) domain parameters, see rl.envs.randomization
    default_joint_pos_rad: torch.Tensor  # (29,) the pose actions are relative to [rad]
    effort_limit_nm: torch.Tensor  # (29,) actuator effort limits [Nm]
    weight_n: float  # nominal robot weight m g [N]
    terminated: torch.Tensor  # (N,) bool, failure this step (all False before terminations run)
    step_dt_s: float  # policy step [s]
    joint_acc_rps2: torch.Tensor  # (N, 29) joint acceleration over the last policy step [rad/s^2]
    joint_pos_limits_rad: torch.Tensor  # (29, 2) lower / upper joint position limits [rad]
    foot_vel_w: torch.Tensor  # (N, 2, 3) left / right sole centre linear velocity [m/s]
    foot_air_time_s: torch.Tensor  # (N, 2) time since each foot left the ground (0 in contact) [s]
    foot_contact_time_s: torch.Tensor  # (N, 2) time since each foot touched down (0 in the air) [s]
    foot_last_air_time_s: torch.Tensor  # (N, 2) duration of each foot's last swing [s]
    foot_first_contact: torch.Tensor  # (N, 2) bool, the foot touched down in this step
    body_ground_contact: torch.Tensor  # (N, B) bool, link b (not a foot) touches the ground
    contact_body_names: tuple[str, ...]  # (B,) body names of ``body_ground_contact``
    # A tracking task's links (SceneConfig.tracked_bodies, K of them; K = 0 for other tasks):
    body_pos_w: torch.Tensor | None = None  # (N, K, 3) link frame positions [m]
    body_quat_w: torch.Tensor | None = None  # (N, K, 4) link orientations, w x y z
    body_lin_vel_w: torch.Tensor | None = None  # (N, K, 3) link linear velocities, world [m/s]
    body_ang_vel_w: torch.Tensor | None = None  # (N, K, 3) link angular velocities, world [rad/s]
    targets: dict[str, torch.Tensor] = field(
        default_factory=dict
    )  # what the command's reference asks of this state beyond the command, for rewards (Command.targets; e.g. body poses (N, K, 3)) [-]

    def to(self, device: str | torch.device) -> EnvState:
        """This state with every tensor on ``device`` (the same tensors where they already are):
        evaluators keep host buffers and read a GPU env's state through this."""
        tensors = {f.name: getattr(self, f.name) for f in fields(self)}
        moved = {k: v.to(device) for k, v in tensors.items() if isinstance(v, torch.Tensor)}
        moved["targets"] = {k: v.to(device) for k, v in self.targets.items()}
        return replace(self, **moved)
