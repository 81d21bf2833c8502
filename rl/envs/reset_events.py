"""Where episodes start and how long they last: the task's initial-state distribution, the episode
counters and the time-outs (the env's reset part)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING

import torch

from rl.envs.declared_state import DeclaredState
from rl.envs.state import quat_multiply
from robots import g1

if TYPE_CHECKING:
    from rl.envs.components import Component
    from rl.envs.physics import Physics
    from rl.envs.task_schema import InitialStateConfig


class ResetEvents(DeclaredState):
    """Initial states around the standing keyframe, and per env the policy steps of its episode
    (``episode_length_buf`` (N,), which runners may overwrite to spread time-outs) and since its
    actual reset (``lived_steps`` (N,))."""

    state_attributes = ("episode_length_buf", "lived_steps")
    """Saved and restored by :class:`~rl.envs.declared_state.DeclaredState`."""

    def __init__(
        self,
        cfg: InitialStateConfig,
        num_envs: int,
        max_episode_length: int,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
    ) -> None:
        """Counters at 0; episodes time out after ``max_episode_length`` policy steps. Counters
        and draws live on ``device`` (the generator's)."""
        self.cfg, self.generator, self.device = cfg, generator, device
        self.max_episode_length = max_episode_length
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long, device=device)
        self.lived_steps = torch.zeros(num_envs, dtype=torch.long, device=device)

    def initial_state(
        self, env_ids: torch.Tensor, physics: Physics, components: Iterable[Component]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Draw the start of ``env_ids`` (M,): joint noise, heading and base velocity around the
        keyframe, then the task's hook and its components' ``reset_state`` edit it in place.
        Returns float64 ``qpos`` (M, 36) and ``qvel`` (M, 35) on this part's device."""
        init, gen, m, dev = self.cfg, self.generator, env_ids.numel(), self.device
        qpos = physics.stand_qpos.to(dev).repeat(m, 1)
        qvel = physics.stand_qvel.to(dev).repeat(m, 1)
        joint_noise = (2 * torch.rand(m, g1.NUM_JOINTS, generator=gen, device=dev) - 1) * (
            init.joint_pos_noise_rad
        )
        qpos[:, 7 : 7 + g1.NUM_JOINTS] += joint_noise.double()
        if init.random_yaw:
            yaw = (2 * torch.rand(m, generator=gen, device=dev) - 1) * math.pi
            zero = torch.zeros(m, device=dev)
            yaw_quat = torch.stack([torch.cos(yaw / 2), zero, zero, torch.sin(yaw / 2)], dim=-1)
            qpos[:, 3:7] = quat_multiply(yaw_quat.double(), qpos[:, 3:7])
        base_vel = (2 * torch.rand(m, 6, generator=gen, device=dev) - 1) * init.base_vel_noise
        qvel[:, 0:6] = base_vel.double()
        if init.reset_state is not None:
            init.reset_state(env_ids, qpos, qvel, gen)
        for component in components:
            component.reset_state(env_ids, qpos, qvel, gen)
        return qpos, qvel

    def restart(self, env_ids: torch.Tensor) -> None:
        """Zero the counters of ``env_ids`` (M,)."""
        self.episode_length_buf[env_ids] = 0
        self.lived_steps[env_ids] = 0

    def advance(self) -> None:
        """Count one policy step."""
        self.episode_length_buf += 1
        self.lived_steps += 1

    def time_outs(self, terminated: torch.Tensor) -> torch.Tensor:
        """(N,) bool: episodes at their length that did not fail (``terminated`` (N,))."""
        return (self.episode_length_buf >= self.max_episode_length) & ~terminated
