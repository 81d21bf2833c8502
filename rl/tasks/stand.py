"""``stand``: stand and balance on both feet under random pushes.

With the G1 gains a PD hold of the stand pose is an unstable equilibrium
(:mod:`robots.standing`), so the policy must learn to balance. The episode fails when the pelvis
drops below ``min_base_height_m`` or tilts beyond ``max_tilt_rad``. Skill progress is the fraction of
recent episodes that survived to the time-out, over ``target_survival``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from rl import rewards
from rl.envs.state import EnvState
from rl.tasks.base import RewardTerm, Task
from robots import g1


@dataclass(frozen=True)
class StandConfig:
    """Targets, limits and reward weights of the stand task."""

    base_height_target_m: float = 0.74  # pelvis height when standing [m]
    min_base_height_m: float = 0.45  # fall: pelvis below this [m]
    max_tilt_rad: float = 0.8  # fall: pelvis z axis tilted more than this from vertical [rad]
    target_survival: float = (
        0.9  # fraction of episodes reaching the time-out that counts as learned [-]
    )
    progress_window: int = 256  # finished episodes in the skill-progress window [-]
    bound_force_n: tuple[float, float, float] = (60.0, 60.0, 150.0)  # default eta, force x y z [N]
    bound_torque_nm: tuple[float, float, float] = (
        20.0,
        20.0,
        10.0,
    )  # default eta, torque x y z [Nm]
    w_alive: float = 1.0  # weight of alive [-]
    w_upright: float = 1.0  # weight of upright [-]
    w_base_height: float = 1.0  # weight of base_height [-]
    w_joint_deviation: float = -0.1  # weight of joint_deviation_l2 [1/rad^2]
    w_action_rate: float = -0.01  # weight of action_rate_l2 [-]
    w_torques: float = -1e-5  # weight of torques_l2 [1/Nm^2]
    w_joint_vel: float = -1e-3  # weight of joint_vel_l2 [s^2/rad^2]
    w_base_lin_vel: float = -0.5  # weight of base_lin_vel_xy_l2 [s^2/m^2]
    w_base_ang_vel: float = -0.05  # weight of base_ang_vel_xy_l2 [s^2/rad^2]
    w_feet_contact: float = 0.5  # weight of feet_contact [-]
    w_termination: float = -50.0  # weight of termination; times dt 0.02 s: -1 per fall [-]
    w_less_assist: float = 1.0  # weight of the less-assist reward when switched on [-]


class StandTask(Task):
    """Stand and balance under pushes; one phase, no command."""

    name = "stand"
    phase_names = ("stand",)

    def __init__(self, cfg: StandConfig = StandConfig()) -> None:
        self.cfg = cfg
        self.less_assist_weight = cfg.w_less_assist
        self._stand = torch.as_tensor(g1.STAND_JOINT_POS_RAD, dtype=torch.float32)
        self._cos_max_tilt = math.cos(cfg.max_tilt_rad)
        self._window = torch.zeros(cfg.progress_window)
        self._count = 0

    def default_assist_bound(self) -> torch.Tensor:
        """eta (1, 6) from the config [N, Nm]."""
        return torch.tensor([[*self.cfg.bound_force_n, *self.cfg.bound_torque_nm]])

    def reward_terms(self) -> dict[str, RewardTerm]:
        """Stand rewards: alive, upright, height, feet down; posture, effort and motion penalties."""
        c = self.cfg
        stand = self._stand
        terms = {
            "alive": RewardTerm(lambda s: rewards.alive(s.base_pos_w), c.w_alive),
            "upright": RewardTerm(lambda s: rewards.upright(s.projected_gravity_b), c.w_upright),
            "base_height": RewardTerm(
                lambda s: rewards.base_height(s.base_pos_w[:, 2], c.base_height_target_m),
                c.w_base_height,
            ),
            "joint_deviation": RewardTerm(
                lambda s: rewards.joint_deviation_l2(s.joint_pos_rad, stand), c.w_joint_deviation
            ),
            "action_rate": RewardTerm(
                lambda s: rewards.action_rate_l2(s.action, s.last_action), c.w_action_rate
            ),
            "torques": RewardTerm(lambda s: rewards.torques_l2(s.joint_torque_nm), c.w_torques),
            "joint_vel": RewardTerm(lambda s: rewards.joint_vel_l2(s.joint_vel_rps), c.w_joint_vel),
            "base_lin_vel": RewardTerm(
                lambda s: rewards.base_lin_vel_xy_l2(s.base_lin_vel_b), c.w_base_lin_vel
            ),
            "base_ang_vel": RewardTerm(
                lambda s: rewards.base_ang_vel_xy_l2(s.base_ang_vel_b), c.w_base_ang_vel
            ),
            "feet_contact": RewardTerm(
                lambda s: rewards.feet_contact(s.foot_contact_force_n), c.w_feet_contact
            ),
            "termination": RewardTerm(
                lambda s: rewards.termination(self.terminated(s)), c.w_termination
            ),
        }
        return terms

    def terminated(self, state: EnvState) -> torch.Tensor:
        """Fallen: pelvis too low, or tilted beyond ``max_tilt_rad``."""
        too_low = state.base_pos_w[:, 2] < self.cfg.min_base_height_m
        # projected gravity z = -cos(tilt)
        too_tilted = -state.projected_gravity_b[:, 2] < self._cos_max_tilt
        return too_low | too_tilted

    def on_episodes_end(
        self, env_ids: torch.Tensor, time_outs: torch.Tensor, lived_steps: torch.Tensor
    ) -> None:
        """Push survived (1) / fell (0) flags into the progress window; episodes cut short by
        a time limit without having lived a full episode say nothing and are skipped."""
        fell = ~time_outs
        survived = time_outs & (lived_steps >= self.max_episode_length)
        counted = fell | survived
        flags = survived[counted].to(torch.float32)[-self._window.numel() :]
        n = flags.numel()
        if n == 0:
            return
        self._window = torch.cat([self._window[n:], flags])
        self._count = min(self._count + n, self._window.numel())

    def skill_progress(self) -> float:
        """Survival fraction of the recent finished episodes over ``target_survival`` (0 before any)."""
        if self._count == 0:
            return 0.0
        survival = float(self._window[-self._count :].mean())
        return survival / self.cfg.target_survival
