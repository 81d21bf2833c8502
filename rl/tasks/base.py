"""The task interface: what a skill (stand, walk, dance, backflip) adds to the generic G1 env.

A task brings its phases, commands, weighted reward terms, termination rule, extra privileged
observations and its measure of skill progress. :class:`rl.envs.G1VecEnv` never branches on the
task's type: it only calls these hooks.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import torch

from rl.envs.state import EnvState


@dataclass(frozen=True)
class RewardTerm:
    """One weighted reward term: ``weight * fn(state)``; ``fn`` returns (N,)."""

    fn: Callable[[EnvState], torch.Tensor]  # maps the env state to a pure term's (N,) value
    weight: float  # weight of the term (negative for penalties) [-]


class Task(ABC):
    """Hooks of one skill. Subclasses set the class attributes and implement the methods.

    Lifecycle, per env step: ``phase`` (before the wrench is applied), physics, then ``rewards``
    via :meth:`reward_terms`, ``terminated``, ``on_episodes_end`` for envs that finish,
    ``reset_state`` and ``reset`` for them, then ``commands`` / ``privileged_extras`` for the
    next observations.
    """

    name: str = ""
    """Registry name."""
    phase_names: tuple[str, ...] = ("main",)
    """One name per phase; the assist bound has one row per phase."""
    command_dim: int = 0
    """Width C of the command appended to the policy observation."""
    extra_privileged_dim: int = 0
    """Width of :meth:`privileged_extras`."""
    less_assist_weight: float = 1.0
    """Weight of the less-assist reward once the runner switches it on."""

    @property
    def num_phases(self) -> int:
        """Number of phases (>= 1)."""
        return len(self.phase_names)

    def bind(self, num_envs: int, generator: torch.Generator, max_episode_length: int) -> None:
        """Allocate per-env task buffers; called once by the env before its first reset.

        ``max_episode_length`` is the episode length [policy steps] of a full episode.
        """
        self.num_envs = num_envs
        self.generator = generator
        self.max_episode_length = max_episode_length

    @abstractmethod
    def default_assist_bound(self) -> torch.Tensor:
        """Initial eta (num_phases, 6) [N, Nm] until the runner sets one (e.g. from the oracle)."""

    @abstractmethod
    def reward_terms(self) -> dict[str, RewardTerm]:
        """Name -> weighted term; logged as ``Reward/<name>``."""

    @abstractmethod
    def terminated(self, state: EnvState) -> torch.Tensor:
        """Failure (N,) bool of each env (not time-outs)."""

    def phase(self, state: EnvState) -> torch.Tensor:
        """Current phase index (N,) long of each env; single-phase tasks return zeros."""
        return torch.zeros(state.base_pos_w.shape[0], dtype=torch.long)

    def commands(self, state: EnvState) -> torch.Tensor:
        """Command (N, C) appended to the policy observation."""
        return torch.zeros(state.base_pos_w.shape[0], self.command_dim)

    def privileged_extras(self, state: EnvState) -> torch.Tensor:
        """Task-specific privileged observation (N, extra_privileged_dim)."""
        return torch.zeros(state.base_pos_w.shape[0], self.extra_privileged_dim)

    def reset_state(  # noqa: B027 - optional hook
        self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor
    ) -> None:
        """Edit in place the initial MuJoCo ``qpos`` (M, 36) and ``qvel`` (M, 35) (float64) of
        resetting envs ``env_ids`` (M,), e.g. to start from a reference frame; default: the noisy
        standing pose the env drew."""

    def reset(self, env_ids: torch.Tensor) -> None:  # noqa: B027 - optional hook
        """Resample per-env task state (commands, phase timers) for ``env_ids`` (M,)."""

    def on_episodes_end(  # noqa: B027 - optional hook
        self, env_ids: torch.Tensor, time_outs: torch.Tensor, lived_steps: torch.Tensor
    ) -> None:
        """Record finished episodes: ``env_ids`` (M,), ``time_outs`` (M,) bool (True: ended by
        the time limit, not by failure), ``lived_steps`` (M,) long: policy steps since the env's
        actual reset (runners may shorten first episodes by starting ``episode_length_buf`` at
        random values; those time out early without having survived a full episode)."""

    @abstractmethod
    def skill_progress(self) -> float:
        """Skill relative to its target, in [0, 1+]; >= 1 means learned."""
