"""What the env remembers between physics reads: the feet's air / contact timers and the joint
acceleration over the last policy step (the env's contact-timer part)."""

from __future__ import annotations

import torch

from rl.envs.declared_state import DeclaredState
from rl.envs.state import FOOT_CONTACT_THRESHOLD_N
from robots import g1


class ContactTimers(DeclaredState):
    """Foot timers (N, 2) [s] with Isaac Lab's contact-sensor semantics (``first_contact`` when a
    foot lands after a swing, ``last_air_time_s`` the length of that swing) and the joint
    acceleration (N, 29) [rad/s^2] from the joint rates of two consecutive steps."""

    state_attributes = (
        "last_joint_vel",
        "joint_acc",
        "foot_air_time_s",
        "foot_contact_time_s",
        "foot_last_air_time_s",
        "foot_first_contact",
    )
    """Saved and restored by :class:`~rl.envs.declared_state.DeclaredState`."""

    def __init__(self, num_envs: int, step_dt_s: float, device: torch.device | str = "cpu") -> None:
        """All timers at 0, no foot just landed; every buffer lives on ``device``."""
        self.step_dt_s, self.device = step_dt_s, device
        self.last_joint_vel = torch.zeros(num_envs, g1.NUM_JOINTS, device=device)
        self.joint_acc = torch.zeros(num_envs, g1.NUM_JOINTS, device=device)
        self.foot_air_time_s = torch.zeros(num_envs, 2, device=device)
        self.foot_contact_time_s = torch.zeros(num_envs, 2, device=device)
        self.foot_last_air_time_s = torch.zeros(num_envs, 2, device=device)
        self.foot_first_contact = torch.zeros(num_envs, 2, dtype=torch.bool, device=device)

    def update(self, joint_vel_rps: torch.Tensor, foot_force_n: torch.Tensor) -> None:
        """Advance one policy step from the new joint rates (N, 29) [rad/s] (kept: pass a tensor
        nobody else edits) and sole normal forces (N, 2) [N]."""
        dt = self.step_dt_s
        self.joint_acc = (joint_vel_rps - self.last_joint_vel) / dt
        self.last_joint_vel = joint_vel_rps
        contact = foot_force_n > FOOT_CONTACT_THRESHOLD_N
        self.foot_first_contact = contact & (self.foot_air_time_s > 0)
        self.foot_last_air_time_s = torch.where(
            self.foot_first_contact, self.foot_air_time_s + dt, self.foot_last_air_time_s
        )
        self.foot_air_time_s = torch.where(contact, 0.0, self.foot_air_time_s + dt)
        self.foot_contact_time_s = torch.where(contact, self.foot_contact_time_s + dt, 0.0)

    def reset(self, env_ids: torch.Tensor, joint_vel_rps: torch.Tensor) -> None:
        """Start ``env_ids`` (M,) afresh from their joint rates (M, 29) [rad/s]."""
        self.last_joint_vel[env_ids] = joint_vel_rps
        self.joint_acc[env_ids] = 0.0
        self.foot_air_time_s[env_ids] = 0.0
        self.foot_contact_time_s[env_ids] = 0.0
        self.foot_last_air_time_s[env_ids] = 0.0
        self.foot_first_contact[env_ids] = False

    def fields(self) -> dict[str, torch.Tensor]:
        """The :class:`rl.envs.state.EnvState` fields of this part."""
        return {
            "joint_acc_rps2": self.joint_acc,
            "foot_air_time_s": self.foot_air_time_s,
            "foot_contact_time_s": self.foot_contact_time_s,
            "foot_last_air_time_s": self.foot_last_air_time_s,
            "foot_first_contact": self.foot_first_contact,
        }
