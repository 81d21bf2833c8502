"""Stateful parts of a task (command generator, phase machine, skill measure); defined in
:mod:`rl.envs.components` (the env's schema, below the tasks) and re-exported here, the import
path task modules use."""

from rl.envs.components import (
    Command,
    CommandColumns,
    Component,
    EpisodeWindow,
    NoCommandConfig,
    PhaseMachine,
    SinglePhaseConfig,
    SkillMeasure,
    SurvivalSkill,
    SurvivalSkillConfig,
)

__all__ = [
    "Command",
    "CommandColumns",
    "Component",
    "EpisodeWindow",
    "NoCommandConfig",
    "PhaseMachine",
    "SinglePhaseConfig",
    "SkillMeasure",
    "SurvivalSkill",
    "SurvivalSkillConfig",
]
