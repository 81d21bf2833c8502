"""The A2CF assistive-force curriculum (paper Algorithm 1), one 6-D bound per task phase.

Each training iteration ``k`` and each phase ``p`` the half-width ``eta[p]`` (force x, y, z [N], then
moment x, y, z [Nm]) of the hypercube that bounds the assistive pelvis wrench is updated from the
applied-wrench magnitude ``|F_k|`` measured over that iteration's rollout:

    if   |F_k| < (1 - epsilon) |eta_k|:  eta_k <- (1 - delta) eta_k
    elif |F_k| > (1 + epsilon) |eta_k|:  eta_k <- (1 + delta) eta_k
    if isSkillLearned:                   eta_k <- (1 - delta) eta_k

Definitions used here (the paper leaves them open; docs/training.md documents them, with what
each measured):

- ``|F_k|`` of a phase is the mean, over every (env, control step) of the iteration's rollout whose
  env was in that phase, of the Euclidean norm of the 6-D applied wrench (``extras["assist"]
  ["applied_wrench"]``, after the random mask and the bound; force [N] and moment [Nm] entries are
  mixed in one norm exactly as the paper's ``|F|``). ``|eta_k|`` is the 6-D norm of the bound.
- ``--curriculum-force-measure quantile`` (an option; the default ``mean`` is the paper's rule)
  replaces that mean by ``q |eta_k|`` with ``q`` the ``force_quantile`` of the per-sample ratio
  ``|F| / |eta|``: the bound shrinks only once even the largest help the agent gives (its 90th
  percentile by default) sits well inside it. An as-needed helper (a warm-started head that is zero
  while the learner is within its tolerance band and saturates when it falls) has a small *mean*
  and the paper's rule shrinks its bound every iteration, whatever it does when help is needed;
  the quantile keeps the bound while help is still needed in more than ``1 - force_quantile`` of
  the states.
- The force rule runs only for phases visited in the iteration (no sample, no measurement); the
  skill-learned decay runs for every phase, so all bounds go to zero once the skill is learned.
- ``isSkillLearned`` is ``progress >= skill_learned_progress``, ``progress`` by
  ``skill_measure``:

  - ``"helped"`` (the paper's, and the default): the iteration's mean of
    ``extras["skill_progress"]``, the skill of the helped envs; the default threshold is 0.6 of
    the target (the paper: 1.0). The decay then *weans*: ``delta`` per iteration while the
    helped skill holds the threshold, paused whenever taking help away drops it below, so the
    bound follows what the pair can do without falling back;
  - ``"evaluation"``: the target progress of the last evaluation of the motion policy alone during
    training (:mod:`rl.evaluation.alone`: assistance off, fresh envs, the policy's mean action;
    :meth:`SkillTarget.progress`, >= 1 where the task's target is reached), noted by the runner
    (:meth:`AssistCurriculum.note_evaluation`): help until the policy alone has the skill;
  - ``"alone"``: the skill of the alone envs' training episodes (below),
    ``extras["skill_progress_alone"]``; under exploration noise it reads lower than the policy's
    mean action would, so it cannot say the skill is learned.
- A share ``alone_share`` of the envs (fixed env ids) never gets help: their finished episodes feed
  a skill window of their own (``alone_window`` episodes), and they give the motion policy
  episodes on its own while the help is on.
- The alone envs' wrench is zero and they are left out of the force rule's statistics (|F| is the
  help given where help is given).
- The less-assist reward is switched on (and stays on) the first iteration with
  ``skill_progress >= less_assist_progress`` (0.8, the paper's 80 %).
- ``anneal_iterations`` N > 0 (default 200, not the paper's; 0 turns it off) caps the bound by a
  fixed schedule, ``eta0 (1 - k / N)`` after the k-th update: the help is gone after N iterations
  whatever the rules measure: the helped skill under exploration noise can stay below the
  trigger long after the policy alone has the skill.
- Assistance is switched off (and stays off) the first iteration in which the applied wrench is
  negligible: ``max`` over visited phases of ``|F_k|`` below ``negligible_force_n`` (paper: 0.1 N,
  "insignificant for a 35 kg robot"), or every bound norm ``|eta[p]|`` below it (the applied
  wrench can then never exceed it).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch

from rl.a2cf.config import CurriculumConfig

RATIO_BINS = 200
"""Histogram bins of the per-sample ratio ``|F| / |eta|`` in [0, 1] (quantile resolution 0.005)."""


def update_bound(
    eta: torch.Tensor,
    applied_norm: torch.Tensor,
    visited: torch.Tensor,
    skill_learned: bool,
    epsilon: float,
    delta: float,
) -> torch.Tensor:
    """One step of Algorithm 1 for every phase at once (pure function).

    Args:
        eta: (P, 6) current bounds (force [N], moment [Nm]).
        applied_norm: (P,) mean applied-wrench norm ``|F_k|`` per phase.
        visited: (P,) bool, phases with at least one sample this iteration (others keep their
            bound under the force rule).
        skill_learned: the task's skill is learned: an extra ``(1 - delta)`` decay on every phase.
        epsilon: tolerance band of the force rule.
        delta: relative change per step.

    Returns:
        (P, 6) the new bounds.
    """
    eta_norm = torch.linalg.vector_norm(eta, dim=-1)
    shrink = visited & (applied_norm < (1.0 - epsilon) * eta_norm)
    grow = visited & ~shrink & (applied_norm > (1.0 + epsilon) * eta_norm)
    scale = torch.ones_like(eta_norm)
    scale = torch.where(shrink, scale * (1.0 - delta), scale)
    scale = torch.where(grow, scale * (1.0 + delta), scale)
    if skill_learned:
        scale = scale * (1.0 - delta)
    return eta * scale.unsqueeze(-1)


def identical_axis_bounds(eta0: torch.Tensor) -> torch.Tensor:
    """The "w/o ID" ablation: per phase, the same bound on x, y, z (mean of the three), for the
    force and, separately, for the moment.

    Args:
        eta0: (P, 6) per-axis initial bounds.

    Returns:
        (P, 6) bounds with ``[f, f, f, m, m, m]`` per phase.
    """
    force = eta0[:, :3].mean(dim=-1, keepdim=True).expand(-1, 3)
    moment = eta0[:, 3:].mean(dim=-1, keepdim=True).expand(-1, 3)
    return torch.cat([force, moment], dim=-1).clone()


@dataclass(frozen=True)
class CurriculumUpdate:
    """What one curriculum step decided (for the caller to apply to the env and to log)."""

    iteration: int  # training iteration the measurement came from [-]
    eta: list[list[float]]  # (P, 6) bounds after the update [N, Nm]
    applied_norm: list[float]  # (P,) measured mean applied-wrench norm [N, Nm mixed]
    visited: list[bool]  # (P,) phases that had samples [-]
    skill_progress: float  # measured skill progress of the helped envs [-]
    alone_progress: float | None  # skill progress of the alone envs (None: no alone envs) [-]
    skill_learned: bool  # extra decay applied [-]
    assist_enabled: bool  # assistance still on after this step [-]
    less_assist_reward: bool  # less-assist reward on after this step [-]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (one line of the curriculum log)."""
        return asdict(self)


class AssistCurriculum:
    """Per-phase hypercube bounds updated by Algorithm 1, plus the two switches of the method.

    The object is pure bookkeeping: it never touches the environment. The runner reads
    :attr:`eta`, :attr:`assist_enabled` and :attr:`less_assist_reward` after :meth:`update` and
    calls the env setters. Its :meth:`state_dict` goes into every checkpoint.
    """

    def __init__(self, eta0: torch.Tensor, cfg: CurriculumConfig = CurriculumConfig()) -> None:
        """Start from the initial bounds ``eta0`` (num_phases, 6), all finite and >= 0."""
        eta0 = torch.as_tensor(eta0, dtype=torch.float32)
        if eta0.ndim != 2 or eta0.shape[1] != 6:
            raise ValueError(
                f"initial assist bound eta0 must have shape (num_phases, 6), got {tuple(eta0.shape)}"
            )
        if not torch.isfinite(eta0).all() or (eta0 < 0).any():
            raise ValueError(f"initial assist bound eta0 must be finite and >= 0, got {eta0}")
        self.cfg = cfg
        self.eta0 = eta0.clone()
        self.eta = eta0.clone()
        self.assist_enabled = True
        self.less_assist_reward = False
        self.num_updates = 0
        self.evaluated_progress = 0.0  # target progress of the last evaluation alone

    def note_evaluation(self, target_progress: float) -> None:
        """Record an evaluation of the motion policy alone (its target progress, >= 1 where the
        task's target is reached): the skill measure ``"evaluation"`` of the next updates."""
        self.evaluated_progress = float(target_progress)

    @property
    def num_phases(self) -> int:
        """Number of task phases (rows of :attr:`eta`)."""
        return int(self.eta.shape[0])

    def update(
        self,
        iteration: int,
        applied_norm: torch.Tensor,
        visited: torch.Tensor,
        skill_progress: float,
        alone_progress: float | None = None,
    ) -> CurriculumUpdate:
        """Apply Algorithm 1 and the two switches after one training iteration.

        Args:
            iteration: index of the iteration the rollout belongs to.
            applied_norm: (P,) mean applied-wrench norm per phase over the rollout.
            visited: (P,) bool, phases with samples in the rollout.
            skill_progress: the helped envs' skill measure (the less-assist switch; the decay
                under ``skill_measure "helped"``).
            alone_progress: the alone envs' skill measure (the decay under ``"alone"``).
        """
        applied_norm = torch.as_tensor(applied_norm, dtype=torch.float32).reshape(-1)
        visited = torch.as_tensor(visited, dtype=torch.bool).reshape(-1)
        if applied_norm.shape[0] != self.num_phases or visited.shape[0] != self.num_phases:
            raise ValueError(
                f"curriculum has {self.num_phases} phases but got applied_norm "
                f"{tuple(applied_norm.shape)} and visited {tuple(visited.shape)}"
            )
        if not torch.isfinite(applied_norm).all():
            raise ValueError(f"applied wrench norm is not finite: {applied_norm}")
        if self.cfg.skill_measure == "evaluation":
            progress = self.evaluated_progress
        elif self.cfg.skill_measure == "alone":
            if alone_progress is None:
                raise ValueError("curriculum skill_measure 'alone' needs the alone envs' progress")
            progress = alone_progress
        else:
            progress = skill_progress
        skill_learned = progress >= self.cfg.skill_learned_progress
        if self.assist_enabled:
            ruled = visited if self.cfg.force_measure != "none" else torch.zeros_like(visited)
            self.eta = update_bound(
                self.eta, applied_norm, ruled, skill_learned, self.cfg.epsilon, self.cfg.delta
            )
            if self.cfg.anneal_iterations > 0:
                left = max(0.0, 1.0 - (self.num_updates + 1) / self.cfg.anneal_iterations)
                self.eta = torch.minimum(self.eta, self.eta0 * left)
            if skill_progress >= self.cfg.less_assist_progress:
                self.less_assist_reward = True
            threshold = self.cfg.negligible_force_n
            force_negligible = (
                bool(visited.any()) and float(applied_norm[visited].max()) < threshold
            )
            bound_negligible = float(torch.linalg.vector_norm(self.eta, dim=-1).max()) < threshold
            if force_negligible or bound_negligible:
                self.assist_enabled = False
                self.less_assist_reward = False  # no assist, no assist penalty
        self.num_updates += 1
        return CurriculumUpdate(
            iteration=iteration,
            eta=self.eta.tolist(),
            applied_norm=applied_norm.tolist(),
            visited=visited.tolist(),
            skill_progress=float(skill_progress),
            alone_progress=None if alone_progress is None else float(alone_progress),
            skill_learned=bool(skill_learned),
            assist_enabled=self.assist_enabled,
            less_assist_reward=self.less_assist_reward,
        )

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue the curriculum after a resume."""
        return {
            "eta0": self.eta0.clone(),
            "eta": self.eta.clone(),
            "assist_enabled": self.assist_enabled,
            "less_assist_reward": self.less_assist_reward,
            "num_updates": self.num_updates,
            "evaluated_progress": self.evaluated_progress,
            "cfg": asdict(self.cfg),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output (the config of this object is kept)."""
        eta = torch.as_tensor(state["eta"], dtype=torch.float32)
        if eta.shape != self.eta.shape:
            raise ValueError(
                f"checkpoint curriculum has bounds of shape {tuple(eta.shape)}, this task needs "
                f"{tuple(self.eta.shape)}: was the checkpoint made for another task?"
            )
        self.eta0 = torch.as_tensor(state["eta0"], dtype=torch.float32).clone()
        self.eta = eta.clone()
        self.assist_enabled = bool(state["assist_enabled"])
        self.less_assist_reward = bool(state["less_assist_reward"])
        self.num_updates = int(state["num_updates"])
        self.evaluated_progress = float(state.get("evaluated_progress", 0.0))
