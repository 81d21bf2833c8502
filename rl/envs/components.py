"""Stateful parts of a task: its command generator, phase machine and skill-progress measure.

A task config names a *config* for each (frozen dataclass with a ``build`` method); the env builds
the live object once, calls its hooks and checkpoints its :meth:`state_dict` (exact resume). The
defaults here serve single-phase tasks without a command; walk, dance and backflip bring their own.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from rl.envs.declared_state import DeclaredState
from rl.envs.state import EnvState


class Component(DeclaredState):  # noqa: B024 - optional hooks; subclasses add the abstract ones
    """Hooks shared by every stateful task part; all optional except what subclasses declare. Its
    state is what it declares in ``state_attributes`` (none here) unless it writes its own
    ``state_dict`` / ``load_state_dict``."""

    def reset(self, env_ids: torch.Tensor) -> None:  # noqa: B027 - optional hook
        """Re-initialise the per-env state of ``env_ids`` (M,) (they start a new episode)."""

    def reset_state(  # noqa: B027 - optional hook
        self,
        env_ids: torch.Tensor,
        qpos: torch.Tensor,
        qvel: torch.Tensor,
        generator: torch.Generator,
    ) -> None:
        """Edit in place the float64 MuJoCo initial state of resetting envs (``qpos`` (M, 36),
        ``qvel`` (M, 35)), e.g. place a robot on its terrain tile or on a reference frame. Called
        before :meth:`reset`, after the task's initial-state noise."""

    def for_evaluation(self) -> None:  # noqa: B027 - optional hook
        """Switch to the finished skill's setting for an evaluation of the policy alone (e.g. a
        command curriculum's full ranges)."""

    def log(self) -> dict[str, float]:
        """Scalars to log this step (e.g. ``Curriculum/terrain_level``); averaged per iteration."""
        return {}


# ------------------------------------------------------------------------------------ commands
@dataclass(frozen=True)
class CommandColumns:
    """A block of consecutive command columns, described for a robot-side script that must
    produce them (the deployment bundle lists a command's blocks in column order)."""

    name: str  # e.g. "lin_vel_x" [-]
    width: int  # number of columns of the block [-]
    unit: str  # unit of every column of the block, e.g. "m/s" [-]
    compute: str  # what the columns hold and how a robot produces them [-]
    from_robot: bool = False
    """the columns also read the robot's measured state (not the command alone) [-]"""


class Command(Component, ABC):
    """Produces the task command (N, C) the policy observes and rewards read."""

    reference_anchor_phase: str | None = None
    """Phase of the oracle artifact whose first frame is time 0 of :meth:`reference_time_s`
    (None: the artifact's first frame). The backflip counts from its start command, which the
    artifact's reference reaches at the start of its Crouch."""

    @abstractmethod
    def compute(self, state: EnvState, dt_s: float) -> torch.Tensor:
        """Advance by one policy step of ``dt_s`` [s] and return the command (N, C)."""

    def columns(self) -> tuple[CommandColumns, ...]:
        """What each column of the command means, as blocks in column order whose widths add up
        to C; empty: not described (the deployment bundle then says so)."""
        return ()

    def reference_time_s(self) -> torch.Tensor | None:
        """Per env, the time along the task's time-indexed reference motion (N,) [s], matching
        the oracle artifact of the same reference (counted from :attr:`reference_anchor_phase`;
        negative: before it); None when the task has none (a coach built from an artifact needs
        it)."""
        return None

    def reference_joint_pos_rad(self) -> torch.Tensor | None:
        """Per env, the reference's joint pose (N, 29) [rad] for the state after the next step
        (what ``--warmstart-motion`` clones the motion head onto); None without a reference."""
        return None

    def describe(self, env: int) -> str:
        """Env ``env``'s command in words for a video's caption ("": nothing to say)."""
        return ""

    def reference_joint_feedforward(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """Per env, the reference's joint rates (N, 29) [rad/s] and planned joint torques
        (N, 29) [N m] for the next step (``action_feedforward``); None without them."""
        return None

    def reference_qpos(self) -> np.ndarray | None:
        """Per env, the MuJoCo qpos (N, 36) of the reference frame the robot is on now (with the
        env's floor offset), float64 on the host; None when the task has no reference motion (a
        video then shows the robot alone)."""
        return None

    def reference_duration_s(self, env: int = 0) -> float | None:
        """Length [s] of the reference env ``env`` tracks (a video of it lasts as long); None
        when the task has no reference motion."""
        return None

    def deployment_reference(self) -> tuple[dict[str, np.ndarray], dict[str, Any]] | None:
        """The reference a deployed policy reads, as its bundle carries it: the arrays of
        ``reference.npz`` and the ``reference`` section of ``policy.json`` that describes them
        (:mod:`rl.agents.bundle`); None when the task tracks no reference."""
        return None

    def targets(self) -> dict[str, torch.Tensor]:
        """What the reference asks of the state after the next step beyond the command (which the
        policy observes), for reward and termination terms (``EnvState.targets``; e.g. a tracking
        task's reference body poses (N, K, 3)); empty: nothing."""
        return {}

    def time_outs(self) -> torch.Tensor | None:
        """(N,) bool, episodes that end now without failing because the command is over (a
        tracking reference's last frame was reached); None: the episode length alone decides."""
        return None


@dataclass(frozen=True)
class NoCommandConfig:
    """No command: an (N, 0) tensor."""

    dim: int = 0  # command width C (always 0 here) [-]

    def build(self, num_envs: int, generator: torch.Generator) -> Command:
        """The live command generator (on the generator's device)."""
        return _NoCommand(num_envs, generator.device)


class _NoCommand(Command):
    def __init__(self, num_envs: int, device: torch.device | str = "cpu") -> None:
        self._empty = torch.zeros(num_envs, 0, device=device)

    def compute(self, state: EnvState, dt_s: float) -> torch.Tensor:
        return self._empty


# ------------------------------------------------------------------------------------- phases
class PhaseMachine(Component, ABC):
    """Maps the env state to each env's phase index (N,) long, before the wrench is applied."""

    @abstractmethod
    def update(self, state: EnvState) -> torch.Tensor:
        """Phase (N,) long of every env after a step (or a reset)."""


@dataclass(frozen=True)
class SinglePhaseConfig:
    """One phase for the whole episode."""

    names: tuple[str, ...] = ("main",)  # the one phase's name [-]

    def build(self, num_envs: int, generator: torch.Generator) -> PhaseMachine:
        """The live phase machine."""
        if len(self.names) != 1:
            raise ValueError(f"SinglePhaseConfig takes exactly one name, got {self.names}")
        return _SinglePhase(num_envs, generator.device)


class _SinglePhase(PhaseMachine):
    def __init__(self, num_envs: int, device: torch.device | str = "cpu") -> None:
        self._zeros = torch.zeros(num_envs, dtype=torch.long, device=device)

    def update(self, state: EnvState) -> torch.Tensor:
        return self._zeros


# -------------------------------------------------------------------------------- skill measure
class EpisodeWindow:
    """The last ``size`` per-episode values (success flags, errors), oldest dropped first. The
    window lives on the device of the values pushed (the env's), so pushes copy nothing."""

    def __init__(self, size: int) -> None:
        self.values = torch.zeros(size)
        self.count = 0
        self._mean: float | None = None  # the mean on the host, read once after each change

    def push(self, values: torch.Tensor) -> None:
        """Append per-episode values (M,) (only the newest ``size`` are kept)."""
        if self.values.device != values.device:  # once: follow the env's device
            self.values = self.values.to(values.device)
        values = values.to(torch.float32)[-self.values.numel() :]
        n = values.numel()
        if n:
            self.values = torch.cat([self.values[n:], values])
            self.count = min(self.count + n, self.values.numel())
            self._mean = None

    def mean(self, empty: float = 0.0) -> float:
        """Mean of the values held (``empty`` before any); read from the device only after a
        push changed it (the env asks every step)."""
        if not self.count:
            return empty
        if self._mean is None:
            self._mean = float(self.values[-self.count :].mean())
        return self._mean

    def state_dict(self) -> dict[str, Any]:
        """Values and fill count."""
        return {"window": self.values.clone(), "count": self.count}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output (the next push moves it to the env's device)."""
        self.values = state["window"].clone()
        self.count = int(state["count"])
        self._mean = None


class SkillMeasure(Component, ABC):
    """Skill relative to its target from finished episodes: >= 1 means learned."""

    @abstractmethod
    def on_episodes_end(
        self,
        env_ids: torch.Tensor,
        time_outs: torch.Tensor,
        lived_steps: torch.Tensor,
        state: EnvState,
    ) -> None:
        """Record finished episodes: ``env_ids`` (M,), ``time_outs`` (M,) bool (ended by the time
        limit, not a failure), ``lived_steps`` (M,) long: policy steps since the env's actual
        reset (runners may start episode counters at random values; such shortened episodes time
        out early without having survived a full episode); ``state`` is the batch state at the
        episodes' last step (before their reset), e.g. for the distance walked."""

    @abstractmethod
    def progress(self) -> float:
        """Skill relative to its target, in [0, 1+]."""

    max_episode_length: int  # policy steps of a full episode (set by the measure's constructor)

    def alone_measure(self) -> SkillMeasure | None:
        """The measure of the alone envs' episodes where it cannot be a fresh build of this one's
        config (one that holds per-env state the task's resets fill, e.g. the walk's terrain
        curriculum); None: a fresh build with its own window."""
        return None

    def counted(self, time_outs: torch.Tensor, lived_steps: torch.Tensor) -> torch.Tensor:
        """Finished episodes a skill window counts: failures, and time-outs after a full episode
        (not those a runner's random episode start cut short)."""
        return ~time_outs | (lived_steps >= self.max_episode_length)


class WindowedSkill(SkillMeasure):
    """The skill measure every task shares: one score per counted finished episode (a task says
    how it scores an episode, :meth:`episode_scores`) in a moving window of ``window`` episodes;
    the window is the measure's whole state."""

    def __init__(self, cfg: Any, window: int, max_episode_length: int) -> None:
        """Keep ``cfg`` (the task's skill config) and an empty window."""
        self.cfg = cfg
        self.max_episode_length = max_episode_length
        self.window = EpisodeWindow(window)

    @abstractmethod
    def episode_scores(
        self, env_ids: torch.Tensor, time_outs: torch.Tensor, state: EnvState
    ) -> torch.Tensor:
        """The score (M,) of each finished episode of ``env_ids`` (M,) from its last state."""

    def on_episodes_end(
        self,
        env_ids: torch.Tensor,
        time_outs: torch.Tensor,
        lived_steps: torch.Tensor,
        state: EnvState,
    ) -> None:
        """Push the scores of the counted finished episodes (:meth:`counted`)."""
        scores = self.episode_scores(env_ids, time_outs, state)
        self.window.push(scores[self.counted(time_outs, lived_steps)])

    def state_dict(self) -> dict[str, Any]:
        """The window."""
        return self.window.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the window."""
        self.window.load_state_dict(state)


@dataclass(frozen=True)
class SurvivalSkillConfig:
    """Skill = fraction of recent finished episodes that survived a full episode, over a target."""

    target_survival: float = 0.9  # survival fraction that counts as learned [-]
    window: int = 256  # finished episodes in the moving window [-]

    def __post_init__(self) -> None:
        if not 0.0 < self.target_survival <= 1.0:
            raise ValueError(f"target_survival must be in (0, 1], got {self.target_survival}")
        if self.window < 1:
            raise ValueError(f"skill window must be >= 1 episode, got {self.window}")

    def build(self, max_episode_length: int) -> SkillMeasure:
        """The live measure for episodes of ``max_episode_length`` policy steps."""
        return SurvivalSkill(self, max_episode_length)


class SurvivalSkill(WindowedSkill):
    """Moving window of survived (1) / fell (0) flags; see :class:`SurvivalSkillConfig`."""

    def __init__(self, cfg: SurvivalSkillConfig, max_episode_length: int) -> None:
        """An empty window of ``cfg.window`` episodes."""
        super().__init__(cfg, cfg.window, max_episode_length)

    def episode_scores(
        self, env_ids: torch.Tensor, time_outs: torch.Tensor, state: EnvState
    ) -> torch.Tensor:
        """Survived: ended by the time limit."""
        return time_outs

    def progress(self) -> float:
        """Survival fraction of the window over ``target_survival`` (0 before any episode)."""
        return self.window.mean() / self.cfg.target_survival
