"""``make_env``: a :class:`G1VecEnv` for a registered task."""

from __future__ import annotations

import dataclasses
from typing import Any

from rl.envs.config import EnvConfig
from rl.envs.vec_env import G1VecEnv


def make_env(task_name: str, num_envs: int, **overrides: Any) -> G1VecEnv:
    """Build the env of task ``task_name`` (see ``rl.tasks.TASKS``) with ``num_envs`` instances.

    ``overrides`` replace fields of :class:`EnvConfig` (e.g. ``seed=1, randomize=False``).
    """
    from rl.tasks import TASKS  # tasks import the env's state types; import them lazily

    if task_name not in TASKS:
        raise ValueError(f"Unknown task '{task_name}'; registered tasks: {sorted(TASKS)}.")
    fields = {f.name for f in dataclasses.fields(EnvConfig)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise ValueError(
            f"make_env: {unknown} are not EnvConfig fields; valid overrides: {sorted(fields)}."
        )
    cfg = EnvConfig(num_envs=num_envs, **overrides)
    return G1VecEnv(cfg, TASKS[task_name]())
