"""Stand-task env variants for the tests (not a test module)."""

from __future__ import annotations

import dataclasses

from rl.envs.task_schema import quiet
from rl.envs.vec_env import G1VecEnv
from rl.tasks.registry import make_env
from rl.tasks.stand.task import STAND


def stand_env(
    num_envs: int,
    *,
    pushes: bool = True,
    randomize: bool = True,
    silent: bool = False,
    link_collisions: bool = True,
    **env_fields,
) -> G1VecEnv:
    """The stand env with pushes / randomisation switched, or ``silent`` (no noise of any kind:
    physics depends only on the actions); ``env_fields`` are EnvConfig fields."""
    task = quiet(STAND) if silent else STAND
    task = dataclasses.replace(
        task,
        pushes=dataclasses.replace(task.pushes, enabled=pushes and task.pushes.enabled),
        randomization=dataclasses.replace(
            task.randomization, enabled=randomize and task.randomization.enabled
        ),
        scene=dataclasses.replace(task.scene, link_collisions=link_collisions),
    )
    return make_env(task, num_envs, **env_fields)
