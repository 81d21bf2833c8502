"""Tasks (skills) for the G1 env: the :class:`Task` interface and the registry :data:`TASKS`."""

from collections.abc import Callable

from rl.envs.factory import make_env
from rl.tasks.base import RewardTerm, Task
from rl.tasks.stand import StandConfig, StandTask

TASKS: dict[str, Callable[[], Task]] = {
    StandTask.name: StandTask,
}
"""Task name -> factory of a task with its default config."""

__all__ = ["TASKS", "RewardTerm", "StandConfig", "StandTask", "Task", "make_env"]
