"""The named terms a task is made of; defined in :mod:`rl.envs.terms` (the env's schema, below the
tasks) and re-exported here, the import path task modules use."""

from rl.envs.terms import (
    ObsGroup,
    ObsTerm,
    RewardTerm,
    Term,
    TermFunc,
    TerminationTerm,
    check_unique,
)

__all__ = [
    "ObsGroup",
    "ObsTerm",
    "RewardTerm",
    "Term",
    "TermFunc",
    "TerminationTerm",
    "check_unique",
]
