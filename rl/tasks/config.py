"""The typed config of a task; defined in :mod:`rl.envs.task_schema` (the env's schema, below the
tasks) and re-exported here, the import path task modules use."""

from rl.envs.task_schema import (
    InitialStateConfig,
    ObservationsConfig,
    PushConfig,
    RandomizationConfig,
    ResetStateFn,
    SceneConfig,
    SkillTarget,
    TaskConfig,
    TerrainFn,
    quiet,
)

__all__ = [
    "InitialStateConfig",
    "ObservationsConfig",
    "PushConfig",
    "RandomizationConfig",
    "ResetStateFn",
    "SceneConfig",
    "SkillTarget",
    "TaskConfig",
    "TerrainFn",
    "quiet",
]
