"""Observation history buffer."""

from __future__ import annotations

import torch


class HistoryBuffer:
    """The last H observations (N, H, D) of every env, oldest first."""

    def __init__(
        self, num_envs: int, length: int, dim: int, device: torch.device | str = "cpu"
    ) -> None:
        self.buffer = torch.zeros(num_envs, length, dim, device=device)

    def push(self, obs: torch.Tensor) -> None:
        """Append observations (N, D), dropping the oldest."""
        self.buffer[:, :-1] = self.buffer[:, 1:].clone()
        self.buffer[:, -1] = obs

    def fill(self, env_ids: torch.Tensor, obs: torch.Tensor) -> None:
        """Fill the whole history of ``env_ids`` (M,) with their observations (M, D) (after reset)."""
        self.buffer[env_ids] = obs.unsqueeze(1).expand(-1, self.buffer.shape[1], -1)

    def flat(self) -> torch.Tensor:
        """History as (N, H * D), oldest first."""
        return self.buffer.reshape(self.buffer.shape[0], -1)
