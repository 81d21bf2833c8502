"""The live stateful parts of a task in the env: command generator, phase machine and skill
measure (protocols in :mod:`rl.envs.components`), with the phase and command they produce."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import torch

if TYPE_CHECKING:
    from rl.envs.components import SkillMeasure
    from rl.envs.state import EnvState
    from rl.envs.task_schema import TaskConfig


class TaskComponents:
    """Built once from the task's configs; ``phase`` (N,) long and ``command`` (N, C) are what
    the last :meth:`update` gave (zeros before the first)."""

    def __init__(
        self,
        task: TaskConfig,
        num_envs: int,
        max_episode_length: int,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
    ) -> None:
        """Build the three components (they share the env's ``generator`` and build their
        tensors on its device, which is ``device``)."""
        self.device = device
        self.command_gen = task.commands.build(num_envs, generator)
        if task.actions_around_reference and self.command_gen.reference_joint_pos_rad() is None:
            raise ValueError(
                f"task '{task.name}': actions_around_reference needs a command with reference "
                f"joints (a tracking task's), but its command is {type(self.command_gen).__name__}; "
                "drop --task-actions-around-reference"
            )
        if task.action_feedforward and (
            not task.actions_around_reference
            or self.command_gen.reference_joint_feedforward() is None
        ):
            raise ValueError(
                f"task '{task.name}': action_feedforward shifts the PD targets around the "
                "reference by its joint rates and planned torques, so it needs "
                "--task-actions-around-reference and a tracking command (--task track "
                "--reference ...); drop --task-action-feedforward"
            )
        self.command = torch.zeros(num_envs, task.commands.dim, device=device)
        self.phase_machine = task.phases.build(num_envs, generator)
        self.skill = task.skill.build(max_episode_length)
        self.alone_skill: SkillMeasure | None = (
            None  # the alone envs' measure (:meth:`track_alone`)
        )
        self._skill_cfg, self._max_episode_length = task.skill, max_episode_length
        self.phase = torch.zeros(num_envs, dtype=torch.long, device=device)
        self.targets: dict[
            str, torch.Tensor
        ] = {}  # the command's reference targets (Command.targets)
        self._no_time_outs = torch.zeros(num_envs, dtype=torch.bool, device=device)
        self.all = (self.command_gen, self.phase_machine, self.skill)

    def track_alone(self, window: int | None) -> None:
        """Measure the alone envs' skill in a window of its own of ``window`` finished episodes
        (the task's skill config with that window); ``None``: no alone envs."""
        if window is None:
            self.alone_skill = None
            return
        shared = self.skill.alone_measure()
        if shared is not None:
            self.alone_skill = shared
            return
        cfg = self._skill_cfg
        if "window" in {f.name for f in dataclasses.fields(cfg)}:
            cfg = dataclasses.replace(cfg, window=window)
        self.alone_skill = cfg.build(self._max_episode_length)

    def on_episodes_end(
        self,
        env_ids: torch.Tensor,
        time_outs: torch.Tensor,
        lived_steps: torch.Tensor,
        state: EnvState,
        alone: torch.Tensor,
    ) -> None:
        """Hand finished episodes (see :meth:`SkillMeasure.on_episodes_end`) to the skill
        measure, those of alone envs (``alone`` (N,) bool) to the alone envs' measure."""
        lone = alone[env_ids]
        if self.alone_skill is None or not lone.any():
            self.skill.on_episodes_end(env_ids, time_outs, lived_steps, state)
            return
        helped = ~lone
        if helped.any():
            self.skill.on_episodes_end(
                env_ids[helped], time_outs[helped], lived_steps[helped], state
            )
        self.alone_skill.on_episodes_end(env_ids[lone], time_outs[lone], lived_steps[lone], state)

    def update(self, state: EnvState, dt_s: float) -> None:
        """Command and phase of the state after a step of ``dt_s`` [s] (0 after a reset). The
        phase machine sees the command's new targets (a tracking task's phases are its target
        frame's); ``state.command`` is still the one the step's action saw."""
        self.command = self.command_gen.compute(state, dt_s)
        self.targets = self.command_gen.targets()
        state.targets = self.targets
        self.phase = self.phase_machine.update(state)

    def time_outs(self) -> torch.Tensor:
        """(N,) bool: episodes the command ends this step (its reference has run out)."""
        ends = self.command_gen.time_outs()
        return self._no_time_outs if ends is None else ends

    def reset(self, env_ids: torch.Tensor) -> None:
        """Every component's :meth:`reset` of ``env_ids`` (M,)."""
        for component in self.all:
            component.reset(env_ids)

    def log(self) -> dict[str, float]:
        """Every component's scalars of this step."""
        return {key: value for component in self.all for key, value in component.log().items()}

    def state_dict(self) -> dict[str, Any]:
        """Phase, command and each component's state."""
        return {
            "phase": self.phase.clone(),
            "command": self.command.clone(),
            "command_gen": self.command_gen.state_dict(),
            "phase_machine": self.phase_machine.state_dict(),
            "skill": self.skill.state_dict(),
            **({"alone_skill": self.alone_skill.state_dict()} if self.alone_skill else {}),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.phase = state["phase"].to(self.device, copy=True)
        self.command = state["command"].to(self.device, copy=True)
        self.command_gen.load_state_dict(state["command_gen"])
        self.targets = self.command_gen.targets()  # the restored command's (the next rewards')
        self.phase_machine.load_state_dict(state["phase_machine"])
        self.skill.load_state_dict(state["skill"])
        if self.alone_skill is not None and "alone_skill" in state:
            self.alone_skill.load_state_dict(state["alone_skill"])
