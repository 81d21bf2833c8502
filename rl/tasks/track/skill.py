"""The tracking task's training skill measure: the joint tracking error of recent episodes."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from rl.envs.state import EnvState
from rl.tasks.dance.skill import TrackingSkill, TrackingSkillConfig
from rl.tasks.track.terms import joint_error_mean_abs


@dataclass(frozen=True)
class MotionSkillConfig(TrackingSkillConfig):
    """Skill = ``threshold_rad`` over the mean joint error of recent episodes (a fall counts as
    ``fall_error_rad``); every finished episode counts, as a reference's end is a time-out."""

    def build(self, max_episode_length: int) -> MotionSkill:
        """The live measure."""
        return MotionSkill(self, max_episode_length)


class MotionSkill(TrackingSkill):
    """Moving window of episode-end joint errors against the tracking targets."""

    log_key = "Skill/track_joint_error_rad"

    def counted(self, time_outs: torch.Tensor, lived_steps: torch.Tensor) -> torch.Tensor:
        """Every finished episode (a time-out is the end of its reference)."""
        return torch.ones_like(time_outs)

    def joint_errors(self, state: EnvState) -> torch.Tensor:
        """Mean absolute joint error (N,) [rad] against the reference frame just targeted."""
        return joint_error_mean_abs(state)
