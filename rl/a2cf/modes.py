"""Training modes compared in the paper (Sec. IV-B): the method and its ablations.

========== ======================================================================================
baseline   no assist agent (DreamWaQ-style motion policy alone); the env's assistance is off
a2cf       motion head + assist head with privileged info, per-axis initial bounds, random mask
no-pi      as a2cf, the assist head does not read the privileged observation
no-id      as a2cf, identical initial bounds on x, y, z (mean of the per-axis eta0), force and
           moment separately
no-rm      as a2cf, random-mask probability zeta = 0
coach      no assist agent; the oracle artifact's coach (``--coach-source``) is the help, scaled by
           the policy's failure rate until it is zero (ZEST's rule, :mod:`rl.a2cf.coach_help`)
========== ======================================================================================
"""

from __future__ import annotations

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from rl.agents.models import ASSIST_ACTION_DIM


class EnvView(VecEnv):
    """A view of an env for the learner: everything is the wrapped env's unless overridden."""

    def __init__(self, env: VecEnv) -> None:
        """Wrap ``env``."""
        self.env = env
        self.num_envs = env.num_envs
        self.num_actions = env.num_actions
        self.max_episode_length = env.max_episode_length
        self.device = env.device
        self.cfg = env.cfg

    @property
    def episode_length_buf(self) -> torch.Tensor:  # type: ignore[override]
        """The wrapped env's episode-length buffer."""
        return self.env.episode_length_buf

    @episode_length_buf.setter
    def episode_length_buf(self, value: torch.Tensor) -> None:
        self.env.episode_length_buf = value

    def __getattr__(self, name: str):
        """Forward everything else (setters, task, num_phases, ...) to the wrapped env."""
        return getattr(self.__dict__["env"], name)

    def get_observations(self) -> TensorDict:
        """The wrapped env's observations."""
        return self.env.get_observations()

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """The wrapped env's step."""
        return self.env.step(actions)


class MotionOnlyEnv(EnvView):
    """View of an A2CF env without the assist action (mode ``baseline``).

    ``num_actions`` is the motion part only; :meth:`step` appends zeros for the assist part (the env
    has assistance disabled anyway, so they have no effect). Everything else is the wrapped env's.
    """

    def __init__(self, env: VecEnv) -> None:
        """Wrap ``env`` (an env with ``num_actions == 29 + 6``)."""
        if env.num_actions <= ASSIST_ACTION_DIM:
            raise ValueError(
                f"env has {env.num_actions} actions, expected motion + {ASSIST_ACTION_DIM} assist"
            )
        super().__init__(env)
        self.num_actions = env.num_actions - ASSIST_ACTION_DIM

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Step with ``[actions, zeros(6)]``."""
        pad = torch.zeros(
            actions.shape[0], ASSIST_ACTION_DIM, dtype=actions.dtype, device=actions.device
        )
        return self.env.step(torch.cat([actions, pad], dim=-1))
