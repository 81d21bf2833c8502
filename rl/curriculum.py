"""The A2CF assistive-force curriculum (paper Algorithm 1), one 6-D bound per task phase.

Each training iteration ``k`` and each phase ``p`` the half-width ``eta[p]`` (force x, y, z [N], then
moment x, y, z [Nm]) of the hypercube that bounds the assistive pelvis wrench is updated from the
applied-wrench magnitude ``|F_k|`` measured over that iteration's rollout:

    if   |F_k| < (1 - epsilon) |eta_k|:  eta_k <- (1 - delta) eta_k
    elif |F_k| > (1 + epsilon) |eta_k|:  eta_k <- (1 + delta) eta_k
    if isSkillLearned:                   eta_k <- (1 - delta) eta_k

Definitions used here (the paper leaves them open; documented in docs/training.md):

- ``|F_k|`` of a phase is the mean, over every (env, control step) of the iteration's rollout whose
  env was in that phase, of the Euclidean norm of the 6-D applied wrench (``extras["assist"]
  ["applied_wrench"]``, after the random mask and the bound; force [N] and moment [Nm] entries are
  mixed in one norm exactly as the paper's ``|F|``). ``|eta_k|`` is the 6-D norm of the bound.
- ``--curriculum-force-measure quantile`` (an option; the default ``mean`` is the paper's rule)
  replaces that mean by ``q |eta_k|`` with ``q`` the ``force_quantile`` of the per-sample ratio
  ``|F| / |eta|``: the bound shrinks only once even the largest help the agent gives (its 90th
  percentile by default) sits well inside it. An as-needed helper (a warm-started head that is zero
  while the learner is within its tolerance band and saturates when it falls) has a small *mean*
  and the paper's rule shrinks its bound every iteration, whatever it does when help is needed
  (measured: ``docs/results/dance_warmstart``); the quantile keeps the bound while help is still
  needed in more than ``1 - force_quantile`` of the states.
- The force rule runs only for phases visited in the iteration (no sample, no measurement); the
  skill-learned decay runs for every phase, so all bounds go to zero once the skill is learned.
- ``isSkillLearned`` is ``progress >= skill_learned_progress``, ``progress`` by
  ``skill_measure``:

  - ``"helped"`` (the paper's, and the default): the iteration's mean of
    ``extras["skill_progress"]``, the skill of the helped envs; the default threshold is 0.6 of
    the target (the paper: 1.0). The decay then *weans*: 20 % per iteration while the helped
    skill holds 0.6, paused whenever taking help away drops it below, so the bound follows what
    the pair can do without falling back (measured on dance: 98 -> 20 over 2 M env steps, the
    helped progress held at 0.60-0.61; with the threshold at 1.0, or with either measure below,
    the bound never moved);
  - ``"evaluation"``: the target progress of the last evaluation of the motion policy alone during
    training (:mod:`rl.alone_eval`: assistance off, fresh envs, the policy's mean action;
    :meth:`SkillTarget.progress`, >= 1 where the task's target is reached), noted by the runner
    (:meth:`AssistCurriculum.note_evaluation`): help until the policy alone has the skill;
  - ``"alone"``: the skill of the alone envs' training episodes (below),
    ``extras["skill_progress_alone"]``. Measured on dance: with the policy's exploration noise
    (std 0.55) they fell every time (progress 0.16) while the same policy's mean action survived
    20-34 % of evaluation episodes: a training measure without help cannot say the skill is
    learned.
- A share ``alone_share`` of the envs (fixed env ids) never gets help: their finished episodes feed
  a skill window of their own (``alone_window`` episodes), and they give the motion policy
  episodes on its own while the help is on.
- The alone envs' wrench is zero and they are left out of the force rule's statistics (|F| is the
  help given where help is given).
- The less-assist reward is switched on (and stays on) the first iteration with
  ``skill_progress >= less_assist_progress`` (0.8, the paper's 80 %).
- ``anneal_iterations`` N > 0 (default 200, not the paper's; 0 turns it off) caps the bound by a
  fixed schedule, ``eta0 (1 - k / N)`` after the k-th update: the help is gone after N iterations
  whatever the rules measure. Measured on stand (3 seeds): without it the weaning left 6-8 of the
  bound for 1-2 M env steps on two seeds (the helped skill under exploration noise stayed below
  0.6 while the policy alone survived 40-80 %), and reached the target on 1 of 3 seeds in 3 M;
  with it 3 of 3.
- Assistance is switched off (and stays off) the first iteration in which the applied wrench is
  negligible: ``max`` over visited phases of ``|F_k|`` below ``negligible_force_n`` (paper: 0.1 N,
  "insignificant for a 35 kg robot"), or every bound norm ``|eta[p]|`` below it (the applied
  wrench can then never exceed it).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
import torch.distributed as dist

from optimal_control.bounds import AXIS_NAMES, PAPER_ETA0
from rl.config_bounds import check_range

WRENCH_AXES: tuple[str, ...] = AXIS_NAMES
"""Names of the six wrench components: force [N] then moment [Nm] at the pelvis, on the axes of
the robot's heading frame (:class:`rl.envs.assist_action.AssistAction`)."""


def paper_bound_rows(paper_task: str) -> tuple[tuple[float, ...], ...]:
    """The paper's hand-set initial bounds of ``paper_task`` ("walk", "dance", "backflip"), one
    6-D row per phase, from the one table :data:`optimal_control.bounds.PAPER_ETA0`."""
    if paper_task not in PAPER_ETA0:
        raise ValueError(
            f"the paper has no initial-bound row for '{paper_task}'; known: {sorted(PAPER_ETA0)}"
        )
    return tuple(tuple(float(v) for v in row) for row in PAPER_ETA0[paper_task]["all"])


FORCE_MEASURES: tuple[str, ...] = ("none", "mean", "quantile")
SKILL_MEASURES: tuple[str, ...] = ("evaluation", "alone", "helped")
"""Whose skill triggers the skill-learned decay (:class:`CurriculumConfig`.skill_measure)."""
"""What ``|F_k|`` of the force rule is (:class:`CurriculumConfig`.force_measure)."""

RATIO_BINS = 200
"""Histogram bins of the per-sample ratio ``|F| / |eta|`` in [0, 1] (quantile resolution 0.005)."""


PAPER_RULES: dict[str, Any] = {
    "force_measure": "mean",
    "skill_measure": "helped",
    "skill_learned_progress": 1.0,
    "alone_share": 0.0,
    "anneal_iterations": 0,
}
"""The :class:`CurriculumConfig` fields that give the paper's Algorithm 1 exactly (the other
defaults are the paper's; the PPO side of the paper adds ``--ppo-assist-init-noise-std 1.0
--ppo-kl-actions all``): ``CurriculumConfig(**PAPER_RULES)``, on the command line
``--curriculum-force-measure mean --curriculum-skill-measure helped
--curriculum-skill-learned-progress 1.0 --curriculum-alone-share 0 --curriculum-anneal-iterations 0``."""


@dataclass(frozen=True)
class CurriculumConfig:
    """Hyper-parameters of the assistive-force curriculum (paper Sec. III-B, Alg. 1)."""

    epsilon: float = 0.5  # tolerance band on |F|/|eta| before the bound moves [-]
    delta: float = 0.2  # relative bound change per update [-]
    negligible_force_n: float = 0.1  # applied-wrench norm under which assistance stops [N]
    less_assist_progress: float = (
        0.8  # helped skill progress that switches on the less-assist reward [-]
    )
    skill_learned_progress: float = 0.6  # progress of skill_measure at which the skill counts as learned: the decay weans the helped skill from 0.6 of its target (the paper: 1.0, never reached in our runs) [-]
    skill_measure: str = "helped"  # whose skill triggers the skill-learned decay: "helped" (the helped envs' training episodes, the paper's), "evaluation" (the last evaluation of the motion policy alone, its target progress) or "alone" (the alone envs' training episodes) [-]
    alone_share: float = (
        0.25  # share of the envs that never get help (fixed env ids); 0: the paper [-]
    )
    alone_window: int = 64  # finished episodes in the alone envs' skill window [-]
    force_measure: str = "none"  # |F_k| of the force rule: "none" (no force rule: the bound moves by the skill-learned decay only), "mean" (the paper) or "quantile" (force_quantile of |F|/|eta|, for as-needed helpers such as a warm start) [-]
    force_quantile: float = (
        0.9  # quantile of the per-sample |F|/|eta| used by force_measure "quantile" [-]
    )
    anneal_iterations: int = 200  # N > 0: a fixed schedule caps the bound at eta0 (1 - k / N) after update k, so the help is gone (assistance off) after N iterations whatever the rules above say (not the paper's; 200 measured on stand and dance at 128 envs: docs/training.md); 0: off (the paper) [-]
    min_phase_samples: int = 1  # a phase needs this many (env, step) samples in a rollout for the force rule; 1 = the paper's rule [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared (values for which Algorithm 1 is
        meaningless); ``--curriculum-*`` are its flags."""
        check_range(self.epsilon, "--curriculum-epsilon", 0.0, 1.0, high_open=True)
        check_range(self.delta, "--curriculum-delta", 0.0, 1.0, low_open=True, high_open=True)
        check_range(self.negligible_force_n, "--curriculum-negligible-force-n", 0.0)
        # a progress no run reaches (even inf) is a rule that never fires: allowed
        check_range(self.less_assist_progress, "--curriculum-less-assist-progress", 0.0)
        check_range(self.skill_learned_progress, "--curriculum-skill-learned-progress", 0.0)
        check_range(self.alone_share, "--curriculum-alone-share", 0.0, 1.0, high_open=True)
        check_range(self.alone_window, "--curriculum-alone-window", 1, 1_000_000)
        check_range(
            self.force_quantile, "--curriculum-force-quantile", 0.0, 1.0, low_open=True,
            high_open=True,
        )  # fmt: skip
        check_range(self.anneal_iterations, "--curriculum-anneal-iterations", 0, 1_000_000_000)
        check_range(self.min_phase_samples, "--curriculum-min-phase-samples", 1, 2**24)
        if self.force_measure not in FORCE_MEASURES:
            raise ValueError(
                f"curriculum force_measure must be one of {FORCE_MEASURES}, got "
                f"'{self.force_measure}'"
            )
        if self.skill_measure not in SKILL_MEASURES:
            raise ValueError(
                f"curriculum skill_measure must be one of {SKILL_MEASURES}, got "
                f"'{self.skill_measure}'"
            )
        if self.skill_measure == "alone" and self.alone_share == 0.0:
            raise ValueError(
                "curriculum skill_measure 'alone' needs alone envs: set alone_share > 0, or "
                "skill_measure 'helped' (the paper)"
            )


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


class AssistStatistics:
    """Accumulates, over one rollout, the applied-wrench norm per phase from ``extras["assist"]``.

    Call :meth:`add` after every env step, :meth:`result` at the end of the rollout, then
    :meth:`reset`.
    """

    def __init__(self, num_phases: int, device: torch.device | str = "cpu") -> None:
        """Zeroed sums for ``num_phases`` phases."""
        self.num_phases = num_phases
        self.norm_sum = torch.zeros(num_phases, dtype=torch.float64, device=device)
        self.count = torch.zeros(num_phases, dtype=torch.float64, device=device)
        self.ratio_hist = torch.zeros(num_phases, RATIO_BINS, dtype=torch.float64, device=device)
        self.axis_abs_sum = torch.zeros(num_phases, 6, dtype=torch.float64, device=device)
        self.force_sum_n = 0.0
        self.steps = 0

    def add(self, assist: dict[str, torch.Tensor]) -> None:
        """Add one step: ``assist["applied_wrench"]`` (N, 6), ``assist["phase"]`` (N,) long and,
        when present, ``assist["bound"]`` (N, 6) (for the histogram of ``|F| / |eta|``)."""
        wrench = assist["applied_wrench"]
        phase = assist["phase"].long().reshape(-1)
        if wrench.ndim != 2 or wrench.shape[1] != 6 or wrench.shape[0] != phase.shape[0]:
            raise ValueError(
                f"extras['assist'] must hold applied_wrench (N, 6) and phase (N,), got "
                f"{tuple(wrench.shape)} and {tuple(phase.shape)}"
            )
        if self.norm_sum.device != wrench.device:  # once: follow the env's device (no copies)
            for key in ("norm_sum", "count", "ratio_hist", "axis_abs_sum"):
                setattr(self, key, getattr(self, key).to(wrench.device))
        norm = torch.linalg.vector_norm(wrench.double(), dim=-1).to(self.norm_sum.device)
        phase = phase.to(self.norm_sum.device)
        self.norm_sum.index_add_(0, phase, norm)
        self.count.index_add_(0, phase, torch.ones_like(norm))
        self.axis_abs_sum.index_add_(0, phase, wrench.double().abs().to(norm.device))
        if "bound" in assist:
            eta = torch.linalg.vector_norm(assist["bound"].double(), dim=-1).to(norm.device)
            ratio = torch.where(eta > 0, norm / eta.clamp_min(1e-12), 0.0).clamp(0.0, 1.0)
            bins = (ratio * RATIO_BINS).long().clamp_max(RATIO_BINS - 1)
            self.ratio_hist.index_put_((phase, bins), torch.ones_like(norm), accumulate=True)
        self.force_sum_n += float(torch.linalg.vector_norm(wrench[:, :3].double(), dim=-1).mean())
        self.steps += 1

    def result(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(applied_norm (P,), visited (P,) bool) over the steps added so far."""
        visited = self.count > 0
        mean = torch.where(visited, self.norm_sum / self.count.clamp(min=1.0), 0.0)
        return mean.float().cpu(), visited.cpu()

    def mean_force_n(self) -> float:
        """Mean norm of the applied force part (3-D) over all env steps added [N]."""
        return self.force_sum_n / max(self.steps, 1)

    def reset(self) -> None:
        """Zero the sums for the next rollout."""
        self.norm_sum.zero_()
        self.count.zero_()
        self.ratio_hist.zero_()
        self.axis_abs_sum.zero_()
        self.force_sum_n = 0.0
        self.steps = 0

    def state_dict(self) -> dict[str, Any]:
        """The running sums (a checkpoint between two steps of a rollout continues exactly)."""
        return {
            "norm_sum": self.norm_sum.clone(),
            "count": self.count.clone(),
            "ratio_hist": self.ratio_hist.clone(),
            "axis_abs_sum": self.axis_abs_sum.clone(),
            "force_sum_n": self.force_sum_n,
            "steps": self.steps,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.norm_sum.copy_(state["norm_sum"])
        self.count.copy_(state["count"])
        for key in ("ratio_hist", "axis_abs_sum"):  # older checkpoints have neither
            if key in state:
                getattr(self, key).copy_(state[key])
        self.force_sum_n = float(state["force_sum_n"])
        self.steps = int(state["steps"])


def histogram_quantile(hist: torch.Tensor, q: float) -> torch.Tensor:
    """Per row of ``hist`` (P, B) over [0, 1]: the upper edge of the bin where the cumulative
    share first reaches ``q`` (0 for an empty row)."""
    total = hist.sum(dim=-1, keepdim=True)
    cum = hist.cumsum(dim=-1) / total.clamp_min(1e-12)
    first = (cum < q - 1e-12).sum(dim=-1)  # bins strictly below the quantile
    edge = (first + 1).double() / hist.shape[-1]
    return torch.where(total.squeeze(-1) > 0, edge.clamp_max(1.0), 0.0)


def _all_reduce_sum(values: torch.Tensor) -> torch.Tensor:
    """Sum ``values`` over the processes of a ``torchrun`` job (identity in a single process)."""
    if dist.is_available() and dist.is_initialized():
        values = values.clone()
        dist.all_reduce(values, op=dist.ReduceOp.SUM)
    return values


class CurriculumEvent:
    """Algorithm 1 as an iteration-rate event of the env: every ``steps_per_iteration`` env steps
    (rsl-rl's ``num_steps_per_env``: one rollout) it updates the bounds from the env's own
    applied-wrench statistics and skill measure.

    The env calls :meth:`on_step` after every step and applies the returned update (bounds and
    switches) before the next one: the timing of the former hand-written loop, with rsl-rl's
    ``OnPolicyRunner.learn`` untouched. Under ``torchrun`` the statistics are summed over all
    processes before the update, so every process moves its bounds identically.
    """

    def __init__(
        self, curriculum: AssistCurriculum, steps_per_iteration: int, iteration: int = 0
    ) -> None:
        """Count rollouts from ``iteration`` (the first one not done yet)."""
        if steps_per_iteration < 1:
            raise ValueError(f"steps_per_iteration must be >= 1, got {steps_per_iteration}")
        self.curriculum = curriculum
        self.steps_per_iteration = int(steps_per_iteration)
        self.iteration = int(iteration)
        self.stats = AssistStatistics(curriculum.num_phases)
        self.step_in_iteration = 0
        self.skill_sum = 0.0
        self.alone_sum = 0.0
        self.history: list[dict[str, Any]] = []
        """One row per update (the curriculum log), checkpointed with the run."""

    def on_step(
        self,
        assist: dict[str, torch.Tensor],
        skill_progress: float,
        alone_progress: float | None = None,
    ) -> dict | None:
        """Record one env step (``assist``: the helped envs' rows); at the end of a rollout
        return the update row, else None."""
        if self.curriculum.assist_enabled:
            self.stats.add(assist)
        self.skill_sum += float(skill_progress)
        if alone_progress is not None:
            self.alone_sum += float(alone_progress)
        self.step_in_iteration += 1
        if self.step_in_iteration < self.steps_per_iteration:
            return None
        sums = _all_reduce_sum(
            torch.cat(
                [  # on the host, once per rollout (the sums live on the env's device)
                    self.stats.norm_sum.cpu(),
                    self.stats.count.cpu(),
                    self.stats.ratio_hist.reshape(-1).cpu(),
                    self.stats.axis_abs_sum.reshape(-1).cpu(),
                    torch.tensor(
                        [
                            self.stats.force_sum_n,
                            float(self.stats.steps),
                            self.skill_sum,
                            self.alone_sum,
                            1.0,
                        ],  # fmt: skip
                        dtype=torch.float64,
                    ),
                ]
            )
        )
        p = self.curriculum.num_phases
        norm_sum, count = sums[:p], sums[p : 2 * p]
        hist_end = 2 * p + p * RATIO_BINS
        hist = sums[2 * p : hist_end].reshape(p, RATIO_BINS)
        axis_abs = sums[hist_end : hist_end + 6 * p].reshape(p, 6) / count.clamp(min=1.0)[:, None]
        force_sum, steps, skill_sum, alone_sum, processes = sums[hist_end + 6 * p :].tolist()
        # A phase seen in only a few samples gives a noisy |F|; below min_phase_samples it
        # counts as unvisited (keeps its bound): rare phases are not shrunk by noise.
        visited = count >= self.curriculum.cfg.min_phase_samples
        mean_norm = torch.where(visited, norm_sum / count.clamp(min=1.0), 0.0).float()
        cfg = self.curriculum.cfg
        ratio_q = histogram_quantile(hist, cfg.force_quantile).float()
        eta_norm = torch.linalg.vector_norm(self.curriculum.eta, dim=-1)
        applied_norm = ratio_q * eta_norm if cfg.force_measure == "quantile" else mean_norm
        skill_progress = skill_sum / (processes * self.steps_per_iteration)
        alone_progress = (
            alone_sum / (processes * self.steps_per_iteration)
            if alone_progress is not None
            else None
        )
        update = self.curriculum.update(
            self.iteration, applied_norm, visited, skill_progress, alone_progress
        )
        row = {
            **update.as_dict(),
            "applied_force_n": force_sum / max(steps, 1.0),
            "mean_applied_norm": mean_norm.tolist(),
            "applied_ratio_quantile": ratio_q.tolist(),
            "applied_abs_per_axis": axis_abs.float().tolist(),
        }
        self.history.append(row)
        self.iteration += 1
        self.stats.reset()
        self.step_in_iteration = 0
        self.skill_sum = self.alone_sum = 0.0
        return row

    def state_dict(self) -> dict[str, Any]:
        """Curriculum, counters, running sums and the update history."""
        return {
            "curriculum": self.curriculum.state_dict(),
            "iteration": self.iteration,
            "step_in_iteration": self.step_in_iteration,
            "skill_sum": self.skill_sum,
            "alone_sum": self.alone_sum,
            "stats": self.stats.state_dict(),
            "history": list(self.history),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.curriculum.load_state_dict(state["curriculum"])
        self.iteration = int(state["iteration"])
        self.step_in_iteration = int(state["step_in_iteration"])
        self.skill_sum = float(state["skill_sum"])
        self.alone_sum = float(state.get("alone_sum", 0.0))  # checkpoints before the alone envs
        self.stats.load_state_dict(state["stats"])
        self.history = list(state["history"])
