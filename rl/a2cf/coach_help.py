"""Training mode ``coach``: the oracle's coach itself is the help, scaled down as the policy stops
failing (the ZEST rule), with no force agent and no A2CF curriculum.

Each step the motion policy acts and the env applies the artifact's coach wrench
(:class:`rl.a2cf.coaches.ArtifactCoach`: the per-frame wrench QP's feed-forward plus PD on the pelvis
pose, at each env's time along the reference) times a per-episode scale

    beta = clip(1 - (1 - failure_rate) / (1 - failure_floor), 0, max_scale)

drawn when the episode starts, from the failure rate of the last ``window`` finished training
episodes (ZEST, reimplemented on mjlab: failure_floor 0.2, max_scale 0.6). Help stops when
failures fall to ``failure_floor``; it returns if they rise again. The judge is, as for every
mode, the policy alone in fresh envs (``--eval-interval``).
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict

from rl.a2cf.config import CoachHelpConfig
from rl.a2cf.modes import MotionOnlyEnv
from rl.envs.components import EpisodeWindow


class CoachHelpEnv(MotionOnlyEnv):
    """The env as the motion policy sees it in mode ``coach``: motion actions only; the assist
    part of each step is the coach's wrench times each env's episode scale."""

    def __init__(self, env: Any, cfg: CoachHelpConfig) -> None:
        """Wrap ``env`` (a :class:`rl.envs.vec_env.G1VecEnv` of a task with a time-indexed
        reference, whose artifact ``cfg.source`` is) and switch its assistance on, bounded by
        the coach's clip, without the less-assist reward or the random mask."""
        from rl.a2cf.coaches import ArtifactCoach

        super().__init__(env)
        self.coach_cfg = cfg
        self.coach = ArtifactCoach(cfg.source)
        cap = [cfg.max_force_n] * 3 + [cfg.max_torque_nm] * 3
        env.set_assist_bound(torch.tensor([cap] * env.num_phases))
        env.set_assist_enabled(True)
        env.set_less_assist_reward(False)
        env.set_random_mask_prob(0.0)
        self.failures = EpisodeWindow(cfg.window)
        self.beta = torch.full((env.num_envs,), cfg.max_scale, device=env.device)

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Step with the policy's motion actions and the scaled coach wrench; episodes that end
        update the failure rate, and the envs they reset draw their scale from it."""
        from rl.envs.assist import raw_from_wrench

        env = self.env
        wrench = self.coach(env) * self.beta.unsqueeze(-1)
        raw = raw_from_wrench(wrench, env.env_state.assist_bound)
        obs, rewards, dones, extras = env.step(torch.cat([actions, raw.to(actions)], dim=-1))
        done = dones.bool()
        if done.any():
            failed = done & ~extras["time_outs"].bool()
            self.failures.push(failed[done].float())
            self.beta[done] = self.coach_cfg.scale(self.failure_rate())
        extras["log"]["Assist/coach_scale"] = float(self.beta.mean())
        extras["log"]["Assist/coach_failure_rate"] = self.failure_rate()
        return obs, rewards, dones, extras

    def failure_rate(self) -> float:
        """Share of failures among the last ``window`` finished episodes (1 before any)."""
        return self.failures.mean(empty=1.0)

    def state_dict(self) -> dict[str, Any]:
        """The env's state, the failure window and the scales (an exact resume)."""
        return {
            **self.env.state_dict(),
            "coach_help": {
                "failures": self.failures.values.clone(),
                "count": self.failures.count,
                "beta": self.beta.clone(),
            },
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        state = dict(state)
        own = state.pop("coach_help")
        self.env.load_state_dict(state)
        self.failures.values = own["failures"].clone()
        self.failures.count = int(own["count"])
        self.beta = own["beta"].to(self.beta.device, copy=True)
