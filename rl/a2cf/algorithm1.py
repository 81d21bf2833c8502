"""Algorithm 1 at the iteration's end: the statistics a rollout gathers (the applied wrench per
phase, the skill measures) and the update of the bounds the runner calls once per iteration,
after PPO's update (:class:`Algorithm1`). :class:`RecordingEnv` is the learner's view of the env
that hands every step to it; the env itself knows no curriculum."""

from __future__ import annotations

from typing import Any

import torch
import torch.distributed as dist
from tensordict import TensorDict

from rl.a2cf.curriculum import RATIO_BINS, AssistCurriculum
from rl.a2cf.modes import EnvView
from rl.envs.assist import WRENCH_AXES
from rl.envs.declared_state import DeclaredState


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


class Algorithm1(DeclaredState):
    """Algorithm 1 of the paper, one update per training iteration.

    :meth:`record` takes every env step of the rollout (the helped envs' ``extras["assist"]``
    rows and the skill measures); :meth:`end_iteration`, which the runner calls once per
    iteration after PPO's update, updates the bounds from the rollout's statistics (summed over
    the processes of a ``torchrun`` job first, so every process moves its bounds identically).
    """

    state_attributes = (
        "curriculum", "iteration", "steps", "skill_sum", "alone_sum", "stats", "history"
    )  # fmt: skip
    """Saved and restored by :class:`~rl.envs.declared_state.DeclaredState`."""

    def __init__(self, curriculum: AssistCurriculum, iteration: int = 0) -> None:
        """Count iterations from ``iteration`` (the first one not done yet)."""
        self.curriculum = curriculum
        self.iteration = int(iteration)
        self.stats = AssistStatistics(curriculum.num_phases)
        self.steps = 0
        self.skill_sum = 0.0
        self.alone_sum = 0.0
        self.alone_measured = False  # the last step brought the alone envs' measure
        self.history: list[dict[str, Any]] = []
        """One row per update (the curriculum log), checkpointed with the run."""

    def record(
        self,
        assist: dict[str, torch.Tensor],
        skill_progress: float,
        alone_progress: float | None = None,
    ) -> None:
        """Add one env step (``assist``: the helped envs' rows)."""
        if self.curriculum.assist_enabled:
            self.stats.add(assist)
        self.skill_sum += float(skill_progress)
        self.alone_measured = alone_progress is not None
        if alone_progress is not None:
            self.alone_sum += float(alone_progress)
        self.steps += 1

    def end_iteration(self) -> dict[str, Any]:
        """Update the bounds from the steps recorded since the last call and return the update
        row (with the alone envs' skill measure when the steps brought one)."""
        sums = _all_reduce_sum(
            torch.cat(
                [  # on the host, once per iteration (the sums live on the env's device)
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
        rollout_steps = processes * max(self.steps, 1)
        skill_progress = skill_sum / rollout_steps
        alone_progress = alone_sum / rollout_steps if self.alone_measured else None
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
        self.steps = 0
        self.skill_sum = self.alone_sum = 0.0
        return row


def curriculum_log(row: dict[str, Any], phase_names: tuple[str, ...]) -> dict[str, float]:
    """TensorBoard scalars ``Curriculum/*`` of an update row of :meth:`Algorithm1.end_iteration`."""
    log = {
        "Curriculum/applied_force_n": float(row["applied_force_n"]),
        "Curriculum/skill_progress": float(row["skill_progress"]),
        **(
            {"Curriculum/skill_progress_alone": float(row["alone_progress"])}
            if row["alone_progress"] is not None
            else {}
        ),  # fmt: skip
        "Curriculum/assist_enabled": float(row["assist_enabled"]),
        "Curriculum/less_assist_reward": float(row["less_assist_reward"]),
    }
    for phase, bounds, norm, applied in zip(
        phase_names, row["eta"], row["applied_norm"], row["applied_abs_per_axis"], strict=True
    ):
        for axis, value, used in zip(WRENCH_AXES, bounds, applied, strict=True):
            log[f"Curriculum/eta_{phase}_{axis}"] = float(value)
            log[f"Curriculum/applied_abs_{phase}_{axis}"] = float(used)
        log[f"Curriculum/applied_wrench_norm_{phase}"] = float(norm)
    return log


class RecordingEnv(EnvView):
    """The env as the learner sees it in the assist modes: every step is also handed to
    :class:`Algorithm1` (the helped envs' rows of ``extras["assist"]``, the skill measures)."""

    def __init__(self, env: Any, algorithm: Algorithm1) -> None:
        """Wrap ``env`` (a :class:`rl.envs.vec_env.G1VecEnv`): its alone envs and the
        curriculum's state are set now."""
        super().__init__(env)
        self.algorithm = algorithm
        use_alone_envs(env, algorithm.curriculum)
        apply_curriculum(env, algorithm.curriculum)

    def end_iteration(self) -> dict[str, Any]:
        """Algorithm 1's update of this iteration, handed to the env; returns its row."""
        row = self.algorithm.end_iteration()
        apply_curriculum(self.env, self.algorithm.curriculum)
        return row

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        """Step the env and record the step."""
        obs, rewards, dones, extras = self.env.step(actions)
        assist, alone = extras["assist"], self.env.assist.alone
        if alone.any():
            assist = {key: value[~alone] for key, value in assist.items()}
        self.algorithm.record(assist, extras["skill_progress"], extras.get("skill_progress_alone"))
        return obs, rewards, dones, extras


def apply_curriculum(env: Any, curriculum: AssistCurriculum) -> None:
    """Hand the curriculum's state to the env: bounds, assistance on or off, less-assist reward."""
    env.set_assist_bound(curriculum.eta)
    env.set_assist_enabled(curriculum.assist_enabled)
    env.set_less_assist_reward(curriculum.less_assist_reward)


def use_alone_envs(env: Any, curriculum: AssistCurriculum | None) -> None:
    """The curriculum's share of alone envs (none without a curriculum)."""
    cfg = curriculum.cfg if curriculum is not None else None
    env.use_alone_envs(cfg.alone_share if cfg else 0.0, cfg.alone_window if cfg else 0)
