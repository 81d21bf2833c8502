"""The task registry, above the env and the tasks (both import neither this nor each other's
registry): task name -> :class:`rl.envs.task_schema.TaskConfig`, and :func:`make_env`.

A new task is one module defining its ``TaskConfig`` plus one line in :data:`TASKS` (or a call of
:func:`register_task` from user code or a test).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from rl.envs.config import EnvConfig
from rl.envs.task_schema import TaskConfig
from rl.envs.vec_env import G1VecEnv
from rl.tasks.backflip.task import BACKFLIP
from rl.tasks.dance.task import DANCE_JOINTS, DANCE_PAPER
from rl.tasks.stand.task import STAND
from rl.tasks.track.command import MotionCommandConfig
from rl.tasks.track.task import DANCE, TRACK, adapt_to_references
from rl.tasks.walk.task import WALK, WALK_FLAT, WALK_PAPER

if TYPE_CHECKING:
    from rl.training.config import TrainConfig

TASKS: dict[str, TaskConfig] = {
    STAND.name: STAND,
    WALK.name: WALK,
    WALK_FLAT.name: WALK_FLAT,
    WALK_PAPER.name: WALK_PAPER,
    BACKFLIP.name: BACKFLIP,
    TRACK.name: TRACK,
    DANCE.name: DANCE,
    DANCE_PAPER.name: DANCE_PAPER,
    "track-paper": dataclasses.replace(DANCE_PAPER, name="track-paper"),
    DANCE_JOINTS.name: DANCE_JOINTS,
}
"""Registered tasks by name, each with its default config."""


def register_task(task: TaskConfig, replace: bool = False) -> None:
    """Add ``task`` to :data:`TASKS` (``replace`` to overwrite a registered name)."""
    if task.name in TASKS and not replace:
        raise ValueError(f"a task named '{task.name}' is already registered")
    TASKS[task.name] = task


def get_task(name: str) -> TaskConfig:
    """The registered task ``name`` or a clear error listing the registered ones."""
    if name not in TASKS:
        raise ValueError(
            f"unknown task '{name}'; registered tasks: {sorted(TASKS)} (see list-tasks)"
        )
    return TASKS[name]


def make_env(task: str | TaskConfig, num_envs: int | None = None, **overrides: Any) -> G1VecEnv:
    """Build the env of ``task`` (a registered name or a config).

    ``num_envs`` and ``overrides`` replace fields of :class:`EnvConfig` (e.g. ``seed=1``).
    """
    task_cfg = get_task(task) if isinstance(task, str) else task
    fields = {f.name for f in dataclasses.fields(EnvConfig)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise ValueError(
            f"make_env: {unknown} are not EnvConfig fields; valid overrides: {sorted(fields)}."
        )
    if num_envs is not None:
        overrides["num_envs"] = num_envs
    return G1VecEnv(EnvConfig(**overrides), task_cfg)


def describe_tasks(history_length: int = EnvConfig.history_length) -> list[dict[str, Any]]:
    """Per registered task: name, description, phases, observation group sizes, term names.

    Builds a one-env instance of each task (about a second each) to measure the group widths.
    """
    rows = []
    for name, task in TASKS.items():
        env = make_env(task, 1, num_threads=1, history_length=history_length)
        try:
            obs = env.get_observations()
            rows.append(
                {
                    "name": name,
                    "description": task.description,
                    "phases": list(task.phase_names),
                    "observation_sizes": {k: int(v.shape[1]) for k, v in obs.items()},
                    "rewards": [t.name for t in task.rewards],
                    "terminations": [t.name for t in task.terminations],
                    "episode_length_s": task.episode_length_s,
                }
            )
        finally:
            env.close()
    return rows


def resolve_task(cfg: TrainConfig) -> TaskConfig:
    """The run's task: the registered config with the run's overrides applied."""
    from rl.a2cf.config import get_mode

    task = get_task(cfg.task).with_overrides(cfg.task_overrides)
    # an assist mode's curriculum works per time bin of the clip the oracle solved
    oracle_phases = bool(cfg.oracle_artifact) and get_mode(cfg.mode).assist
    return with_references(
        task, cfg.reference, cfg.reference_frames, cfg.oracle_artifact, oracle_phases
    )


def with_references(
    task: TaskConfig,
    references: tuple[str, ...],
    frames: str,
    oracle: str = "",
    oracle_phases: bool = False,
) -> TaskConfig:
    """``task`` tracking ``references`` (segment ``frames``, "A:B") with the oracle artifact
    ``oracle`` solved on them (its planned torques; with ``oracle_phases`` its time bins as the
    task's phases); unchanged when none is given. A task whose command tracks no reference
    refuses them in one line."""
    if not references and not frames and not oracle:
        return task
    fields = {f.name for f in dataclasses.fields(task.commands)}
    wanted: dict[str, Any] = {"sources": tuple(references)} if references else {}
    if frames:
        wanted["frames"] = frames
    if oracle:
        wanted.update(oracle=oracle, oracle_phases=oracle_phases)
    missing = sorted(set(wanted) - fields)
    if missing:
        flag = (
            "--reference"
            if "sources" in missing
            else "--reference-frames"
            if "frames" in missing
            else "--oracle"
        )
        raise ValueError(
            f"task '{task.name}' takes no {flag}: it tracks no reference motion of a user's; use "
            "--task track"
        )
    task = dataclasses.replace(task, commands=dataclasses.replace(task.commands, **wanted))
    return adapt_to_references(task) if isinstance(task.commands, MotionCommandConfig) else task
