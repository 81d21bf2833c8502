"""The tracking task's phases where its references have them (an oracle artifact's: the
backflip's stand, crouch, jump, air, land): each env is in the phase of the reference frame it is
asked to reach next, so eta0 and the A2CF curriculum work per phase as on the FSM tasks."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from rl.envs.components import PhaseMachine
from rl.envs.state import EnvState


@dataclass(frozen=True)
class ReferencePhaseConfig:
    """The phases the references name (every reference must have these, in this order)."""

    names: tuple[str, ...]  # the references' phase names [-]

    def build(self, num_envs: int, generator: torch.Generator) -> PhaseMachine:
        """The live phase machine."""
        if not self.names:
            raise ValueError("ReferencePhaseConfig needs the references' phase names")
        return ReferencePhases(num_envs, generator.device)


class ReferencePhases(PhaseMachine):
    """The phase of each env's target frame (``state.targets["phase"]``, which the tracking
    command computes before the phase is read)."""

    def __init__(self, num_envs: int, device: torch.device | str = "cpu") -> None:
        self._zeros = torch.zeros(num_envs, dtype=torch.long, device=device)

    def update(self, state: EnvState) -> torch.Tensor:
        """(N,) long: the target frame's phase (0 before the command has run)."""
        phase = state.targets.get("phase") if state.targets else None
        return self._zeros if phase is None else phase.clone()
