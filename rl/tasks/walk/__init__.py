"""The ``walk`` task as a package: one module per job.

- :mod:`~rl.tasks.walk.task`: the :class:`~rl.tasks.config.TaskConfig` (``WALK``, ``WALK_FLAT``,
  ``WALK_PAPER``) and its observation, reward and command tables, re-exported here;
- :mod:`~rl.tasks.walk.terms`: the walk's reward terms and the height scan;
- :mod:`~rl.tasks.walk.command`: the velocity command (with gait clock and command curriculum);
- :mod:`~rl.tasks.walk.curriculum`: the terrain and its terrain curriculum (the skill measure);
- :mod:`~rl.tasks.walk.evaluation`: ``a2cf-mb eval``'s walk metrics and plot.
"""

from rl.tasks.walk.command import VelocityCommand, VelocityCommandConfig
from rl.tasks.walk.curriculum import WALK_TERRAIN, TerrainCurriculum, TerrainCurriculumConfig
from rl.tasks.walk.task import (
    HEIGHT_SCAN,
    HIP_ROLL_YAW_JOINTS,
    UPPER_BODY_JOINTS,
    WALK,
    WALK_COMMANDS,
    WALK_FLAT,
    WALK_OBSERVATIONS,
    WALK_PAPER,
    WALK_REWARDS,
)

__all__ = [
    "HEIGHT_SCAN",
    "HIP_ROLL_YAW_JOINTS",
    "UPPER_BODY_JOINTS",
    "WALK",
    "WALK_COMMANDS",
    "WALK_FLAT",
    "WALK_OBSERVATIONS",
    "WALK_PAPER",
    "WALK_REWARDS",
    "WALK_TERRAIN",
    "TerrainCurriculum",
    "TerrainCurriculumConfig",
    "VelocityCommand",
    "VelocityCommandConfig",
]
