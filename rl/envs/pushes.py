"""Random pushes: horizontal pelvis velocity kicks at random intervals (the env's push part)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import torch

from rl.envs.declared_state import DeclaredState

if TYPE_CHECKING:
    from rl.envs.physics import Physics
    from rl.envs.task_schema import PushConfig


class Pushes(DeclaredState):
    """Per-env push timers (N,) [s]; an env whose timer runs out gets a uniform horizontal kick of
    at most ``train_velocity_xy_mps`` per axis in training (``velocity_xy_mps`` where that is 0,
    and after :meth:`for_evaluation`) and a new interval from ``interval_range_s``."""

    state_attributes = ("timer_s",)
    """Saved and restored by :class:`~rl.envs.declared_state.DeclaredState`."""

    def __init__(
        self,
        cfg: PushConfig,
        num_envs: int,
        step_dt_s: float,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
    ) -> None:
        """Timers start at 0; :meth:`reset` draws them. Tensors and draws live on ``device``
        (the generator's)."""
        self.cfg, self.step_dt_s, self.generator, self.device = cfg, step_dt_s, generator, device
        self.timer_s = torch.zeros(num_envs, device=device)
        self.velocity_xy_mps = cfg.train_velocity_xy_mps or cfg.velocity_xy_mps
        self.backward_share = cfg.train_backward_share

    def for_evaluation(self) -> None:
        """Push as the skill is judged: at most ``velocity_xy_mps``."""
        self.velocity_xy_mps = self.cfg.velocity_xy_mps
        self.backward_share = 0.0

    def apply(self, physics: Physics) -> None:
        """Count one policy step down and kick the envs whose timer ran out (before the physics)."""
        if not self.cfg.enabled:
            return
        self.timer_s -= self.step_dt_s
        ids = (self.timer_s <= 0).nonzero().flatten()
        if ids.numel() == 0:
            return
        vmax = self.velocity_xy_mps
        kick = (
            2 * torch.rand(ids.numel(), 2, generator=self.generator, device=self.device) - 1
        ) * vmax
        if self.backward_share > 0:
            kick = self._backward(kick, physics.qpos[ids, 3:7].float())
        physics.qvel[ids, 0:2] += kick.double()
        self.timer_s[ids] = self._interval(ids.numel())

    def _backward(self, kick: torch.Tensor, quat: torch.Tensor) -> torch.Tensor:
        """``kick`` (M, 2) [world] with ``backward_share`` of the rows turned backwards: their
        component along the robot's heading (from the pelvis ``quat`` (M, 4) w x y z) made
        negative, the sideways one kept."""
        w, x, y, z = quat.unbind(-1)
        yaw = torch.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        heading = torch.stack([torch.cos(yaw), torch.sin(yaw)], dim=-1)
        turn = torch.rand(kick.shape[0], generator=self.generator, device=self.device)
        forward = (kick * heading).sum(-1)
        flip = (turn < self.backward_share) & (forward > 0)
        return kick - torch.where(flip, 2 * forward, 0.0).unsqueeze(-1) * heading

    def reset(self, env_ids: torch.Tensor) -> None:
        """Draw the next push time of ``env_ids`` (M,) (drawn with pushes off too, which keeps
        the random stream of a seed what it has always been)."""
        self.timer_s[env_ids] = self._interval(env_ids.numel())

    def _interval(self, num: int) -> torch.Tensor:
        low, high = self.cfg.interval_range_s
        return low + (high - low) * torch.rand(num, generator=self.generator, device=self.device)
