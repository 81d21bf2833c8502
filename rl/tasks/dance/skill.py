"""The dance's skill measure: the mean joint tracking error of recent episodes."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from rl.envs.components import SkillMeasure, WindowedSkill
from rl.envs.state import EnvState
from rl.tasks.dance.terms import joint_error_mean_abs


@dataclass(frozen=True)
class TrackingSkillConfig:
    """Skill = ``threshold_rad`` over the mean joint tracking error of recent episodes.

    Each counted episode contributes its mean absolute joint error at its last step (the
    :class:`SkillMeasure` hook sees the episode's last state only), a fall ``fall_error_rad``.
    """

    threshold_rad: float = 0.16  # joint tracking error that counts as learned (paper) [rad]
    fall_error_rad: float = 1.0  # error charged for an episode that fell [rad]
    window: int = 256  # counted episodes in the moving window [-]

    def __post_init__(self) -> None:
        if self.threshold_rad <= 0 or self.window < 1:
            raise ValueError(f"need threshold_rad > 0 and window >= 1, got {self}")

    def build(self, max_episode_length: int) -> SkillMeasure:
        """The live measure."""
        return TrackingSkill(self, max_episode_length)


class TrackingSkill(WindowedSkill):
    """Moving window of episode tracking errors (see :class:`TrackingSkillConfig`)."""

    log_key = "Skill/dance_joint_error_rad"  # the window's mean in the training log

    def __init__(self, cfg: TrackingSkillConfig, max_episode_length: int) -> None:
        """An empty window of ``cfg.window`` episodes."""
        super().__init__(cfg, cfg.window, max_episode_length)

    def episode_scores(
        self, env_ids: torch.Tensor, time_outs: torch.Tensor, state: EnvState
    ) -> torch.Tensor:
        """The joint error of each episode's last step; a fall is charged ``fall_error_rad``."""
        err = self.joint_errors(state)[env_ids]
        return torch.where(time_outs, err, torch.full_like(err, self.cfg.fall_error_rad))

    def joint_errors(self, state: EnvState) -> torch.Tensor:
        """Mean absolute joint error of every env's last step (N,) [rad], against its command."""
        return joint_error_mean_abs(state)

    def mean_error_rad(self) -> float:
        """Mean error of the window [rad] (inf before any counted episode)."""
        return self.window.mean(empty=math.inf)

    def progress(self) -> float:
        """``threshold / mean error`` (>= 1: learned; 0 before any episode)."""
        err = self.mean_error_rad()
        return self.cfg.threshold_rad / err if math.isfinite(err) and err > 0 else 0.0

    def log(self) -> dict[str, float]:
        """The window's mean episode-end joint error."""
        return {self.log_key: self.mean_error_rad()} if self.window.count else {}
