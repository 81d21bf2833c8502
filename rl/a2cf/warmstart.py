"""Warm start of the force agent: the assist head distilled from a coach before PPO starts.

DAgger-style: the env runs with the learner's motion policy acting (so the states are those the
learner visits) while the applied assist wrench is the coach's in the first round and the
student's own afterwards; every visited state is labelled with the coach's wrench. The assist
head's mean, through the bound and the squash (``eta * tanh(raw)``), is regressed onto the labels
(error in units of the bound, axes with a zero bound skipped); then its initial std is set.
The fit per axis on held-out states is reported (``warmstart.json`` in the run folder).

``--warmstart-motion`` clones the motion head the same way from a time-indexed reference's joint
targets (:func:`distill_motion_head`). :func:`warm_start` runs both for a run (the coach chosen by
:func:`choose_coach`), :func:`warmstart_eta0` reads the initial bounds of an oracle artifact.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from tensordict import TensorDict

from rl.a2cf.config import WarmStartConfig
from rl.agents.models import A2CFActor
from rl.envs.assist import WRENCH_AXES, raw_from_wrench
from rl.envs.vec_env import G1VecEnv
from robots import g1

if TYPE_CHECKING:
    from rl.envs.task_schema import TaskConfig
    from rl.training.config import TrainConfig

Coach = Callable[[G1VecEnv], torch.Tensor]
"""A coach: the env (its ``env_state``, and for reference-tracking coaches its command's time along
the reference) -> pelvis wrench (N, 6) [N, Nm] in the robot's heading frame (the assist action's
frame, :class:`rl.envs.assist_action.AssistAction`), within the current bound."""


def _assist_mean(actor: A2CFActor, obs: TensorDict) -> torch.Tensor:
    return actor(obs)[:, g1.NUM_JOINTS :]


def _loss(raw: torch.Tensor, target: torch.Tensor, bound: torch.Tensor) -> torch.Tensor:
    """Squared error of ``eta * tanh(raw)`` against the label, in units of the bound."""
    used = (bound > 0).float()
    err = (bound * torch.tanh(raw) - target) / bound.clamp_min(1e-9) * used
    return err.square().sum() / used.sum().clamp_min(1.0)


def _dagger(
    actor: A2CFActor,
    env: G1VecEnv,
    cfg: WarmStartConfig,
    label: Callable[[G1VecEnv], tuple[torch.Tensor, torch.Tensor]],
    expert: Callable[[torch.Tensor, torch.Tensor, torch.Tensor, int], None],
    output: Callable[[TensorDict], torch.Tensor],
    loss: Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor],
    params: list[torch.nn.Parameter],
) -> tuple[TensorDict, torch.Tensor, torch.Tensor, int]:
    """The DAgger loop shared by both heads: ``cfg.rounds`` rounds of ``cfg.steps_per_round`` env
    steps with the learner acting, every state labelled by ``label(env) -> (target, aux)``;
    ``expert(actions, target, aux, round)`` edits the actions in place (round 0: the expert's),
    then ``cfg.epochs`` passes of Adam on ``loss(output(obs), target, aux)`` over ``params``.

    Returns the held-out part of the last round (obs, target, aux) and the dataset size.
    """
    generator = torch.Generator().manual_seed(cfg.seed)
    optimizer = torch.optim.Adam(params, lr=cfg.learning_rate)
    data: dict[str, list] = {"obs": [], "target": [], "aux": [], "round": []}
    obs = env.get_observations()
    for rnd in range(cfg.rounds):
        with torch.no_grad():
            for _ in range(cfg.steps_per_round):
                target, aux = label(env)
                actor.update_normalization(obs)
                actions = actor(obs, stochastic_output=True)
                expert(actions, target, aux, rnd)
                data["obs"].append(obs.clone())
                data["target"].append(target)
                data["aux"].append(aux)
                data["round"].append(torch.full((target.shape[0],), rnd))
                obs, _, _, _ = env.step(actions)
        all_obs = torch.cat(data["obs"])
        target, aux = torch.cat(data["target"]), torch.cat(data["aux"])
        rounds = torch.cat(data["round"])
        last = torch.nonzero(rounds == cfg.rounds - 1).flatten()
        held = last[
            torch.randperm(last.numel(), generator=generator)[: int(cfg.held_out * last.numel())]
        ]
        train_mask = torch.ones(target.shape[0], dtype=torch.bool)
        train_mask[held] = False
        train_ids = train_mask.nonzero().flatten()
        for _ in range(cfg.epochs):
            order = train_ids[torch.randperm(train_ids.numel(), generator=generator)]
            for start in range(0, order.numel(), cfg.batch_size):
                idx = order[start : start + cfg.batch_size]
                value = loss(output(all_obs[idx]), target[idx], aux[idx])
                optimizer.zero_grad()
                value.backward()
                optimizer.step()
    return all_obs[held], target[held], aux[held], int(target.shape[0])


def distill_assist_head(
    actor: A2CFActor, env: G1VecEnv, coach: Coach, cfg: WarmStartConfig = WarmStartConfig()
) -> dict[str, Any]:
    """Distil ``coach`` into ``actor``'s assist head in ``env`` (see the module docstring).

    Returns the report: per-axis RMSE [N, Nm] and R^2 on held-out states, the coach's and the
    warm-started head's mean |wrench| there, dataset size.
    """
    if actor.mlp.assist is None:
        raise ValueError("the warm start needs an assist head (mode a2cf or an ablation)")

    def label(e: G1VecEnv) -> tuple[torch.Tensor, torch.Tensor]:
        return coach(e), e.env_state.assist_bound.clone()

    def expert(actions, target, bound, rnd) -> None:
        if rnd == 0:
            actions[:, g1.NUM_JOINTS :] = raw_from_wrench(target, bound)

    obs, target, bound, num = _dagger(
        actor, env, cfg, label, expert, lambda o: _assist_mean(actor, o), _loss,
        list(actor.mlp.assist.parameters()),
    )  # fmt: skip
    actor._set_assist_std(cfg.assist_std)
    return _report(actor, obs, target, bound, cfg, num)


def require_joint_reference(env: G1VecEnv) -> None:
    """Refuse ``--warmstart-motion`` on a task whose command has no joint reference, or whose
    actions are already around it (zero action follows the reference: nothing to clone)."""
    if env.command_gen.reference_joint_pos_rad() is None:
        raise ValueError(
            f"--warmstart-motion needs a time-indexed joint reference; task '{env.task.name}' "
            "has none (its command gives no reference_joint_pos_rad): use it with dance"
        )
    if env.task.actions_around_reference:
        raise ValueError(
            f"--warmstart-motion: task '{env.task.name}' has its actions around the reference "
            "already (zero action follows it), so there is nothing to clone; drop the flag, or "
            "add --no-task-actions-around-reference"
        )


def distill_motion_head(
    actor: A2CFActor, env: G1VecEnv, cfg: WarmStartConfig = WarmStartConfig()
) -> dict[str, Any]:
    """``--warmstart-motion``: clone the motion head from the task's time-indexed reference.

    The label of a state is the motion action whose PD target is the reference's joint pose of the
    next step (``env.joint_targets_to_actions(command.reference_joint_pos_rad())``). DAgger as for
    the assist head: round 0 plays the reference's actions, later rounds the learner's own (with
    its exploration noise); no assist wrench meanwhile (raw assist 0). Only the motion MLP learns;
    the motion std is left as configured. Report: per body part RMSE of the cloned joint targets
    [rad] and R^2 on held-out states.
    """
    require_joint_reference(env)
    nj = g1.NUM_JOINTS

    def label(e: G1VecEnv) -> tuple[torch.Tensor, torch.Tensor]:
        target = e.joint_targets_to_actions(e.command_gen.reference_joint_pos_rad())
        return target, torch.zeros(target.shape[0], 1)

    def expert(actions, target, aux, rnd) -> None:
        actions[:, nj:] = 0.0
        if rnd == 0:
            actions[:, :nj] = target

    def output(o: TensorDict) -> torch.Tensor:
        return actor(o)[:, :nj]

    def loss(out, target, aux) -> torch.Tensor:
        return (out - target).square().mean()

    obs, target, _, num = _dagger(
        actor, env, cfg, label, expert, output, loss, list(actor.mlp.motion.parameters())
    )
    with torch.no_grad():
        scale = torch.as_tensor(g1.ACTION_SCALE_RAD, dtype=torch.float32)
        err_rad = (output(obs) - target) * scale
        var = (target * scale).var(dim=0)
    parts = {
        part: {
            "rmse_rad": float(err_rad[:, idx].square().mean().sqrt()),
            "r2": 1.0 - float(err_rad[:, idx].square().mean(0).sum() / var[idx].sum()),
        }
        for part, idx in g1.BODY_PARTS.items()
    }
    return {
        "config": asdict(cfg),
        "samples": num,
        "held_out_samples": int(target.shape[0]),
        "held_out_fit": parts,
        "rmse_rad": float(err_rad.square().mean().sqrt()),
        "r2": 1.0 - float(err_rad.square().mean(0).sum() / var.sum()),
    }


def _report(actor, obs, target, bound, cfg, num_samples) -> dict[str, Any]:
    with torch.no_grad():
        applied = bound * torch.tanh(_assist_mean(actor, obs))
    err = applied - target
    var = target.var(dim=0)
    per_axis = {}
    for i, axis in enumerate(WRENCH_AXES):
        rmse = float(err[:, i].square().mean().sqrt())
        r2 = 1.0 - float(err[:, i].square().mean() / var[i]) if var[i] > 1e-12 else math.nan
        per_axis[axis] = {
            "rmse": rmse,
            "r2": r2,
            "coach_mean_abs": float(target[:, i].abs().mean()),
            "head_mean_abs": float(applied[:, i].abs().mean()),
        }
    return {
        "config": asdict(cfg),
        "samples": int(num_samples),
        "held_out_samples": int(target.shape[0]),
        "share_of_states_helped": float((target.abs().sum(dim=-1) > 1e-6).float().mean()),
        "held_out_fit": per_axis,
        "loss_held_out": float(_loss(_assist_mean(actor, obs), target, bound).detach()),
    }


# ------------------------------------------------------------------ the warm start of a run
def warmstart_eta0(cfg: TrainConfig, task: TaskConfig) -> torch.Tensor | None:
    """eta0 from the oracle artifact named by ``--warmstart``, else (in a mode with an assist
    head) from the run's oracle artifact (``--oracle``); None for neither (a built-in coach).

    The artifact's task and phases must be the training task's."""
    from rl.a2cf.coaches import COACHES
    from rl.a2cf.config import get_mode

    source = cfg.warmstart if cfg.warmstart not in COACHES else ""
    if not source and get_mode(cfg.mode).assist:
        source = cfg.oracle_artifact
    if not source:
        return None
    from optimal_control.artifact import SUMMARY_FILE, OracleArtifact

    folder = Path(source)
    if not (folder / SUMMARY_FILE).is_file():
        raise ValueError(
            f"--warmstart '{source}' is neither a built-in coach ({sorted(COACHES)}) nor an "
            f"oracle artifact folder (no {SUMMARY_FILE}): run a2cf-mb solve-* first"
        )
    summary = OracleArtifact.read_summary(folder)
    eta0 = torch.tensor(summary.eta0, dtype=torch.float32)
    # a tracking task on the artifact's own motion takes it, whatever the artifact was solved as
    takes = (task.name, *task.oracle_tasks)
    if not _tracks_the_artifacts_motion(folder, task) and summary.task not in takes:
        raise ValueError(
            f"--warmstart artifact {folder} is for task '{summary.task}', the training "
            f"task '{task.name}' takes artifacts of {list(takes)}: solve the oracle for one of them"
        )
    if summary.phase_names == task.phase_names:
        return eta0
    if task.num_phases == 1:
        return eta0.max(dim=0, keepdim=True).values  # one bound covering every oracle phase
    raise ValueError(
        f"--warmstart artifact {folder} has phases {list(summary.phase_names)}; the training "
        f"task '{task.name}' has phases {list(task.phase_names)}"
    )


def _tracks_the_artifacts_motion(folder: Path, task: TaskConfig) -> bool:
    """Whether ``task`` tracks references (``commands.sources``) and one of them (after its
    ``--reference-frames`` segment) is the motion the artifact in ``folder`` was solved on.

    Raises:
        ValueError: for a tracking task none of whose references is the artifact's motion (its
            warm start would teach the help of another motion).
    """
    sources = getattr(task.commands, "sources", None)
    if sources is None:
        return False
    from optimal_control.reference_sources import (
        load_reference,
        parse_frames,
        reference_fingerprint,
    )
    from rl.tasks.track.library import at_policy_rate, load_track_reference

    frames = parse_frames(getattr(task.commands, "frames", ""))
    step = task.commands.step_dt_s  # both at the policy rate (a backflip artifact is finer)
    solved = reference_fingerprint(at_policy_rate(load_reference(folder), step))
    trained = [reference_fingerprint(load_track_reference(s, frames, step)) for s in sources]
    if solved in trained:
        return True
    segment = f" (frames {task.commands.frames})" if frames else ""
    raise ValueError(
        f"--warmstart artifact {folder} was solved on another motion than the task '{task.name}' "
        f"tracks ({', '.join(sources)}{segment}): solve the oracle on the same reference "
        f"(e.g. a2cf-mb solve-dance --clip FILE), or pass --reference {folder}"
    )


def choose_coach(source: str, env: G1VecEnv) -> tuple[Coach, str]:
    """The coach ``--warmstart source`` names (a built-in coach or an oracle artifact folder) for
    ``env``'s task, and a sentence saying which it is (for ``warmstart.json``)."""
    from rl.a2cf.coaches import COACHES, ArtifactCoach

    if source in COACHES:
        return COACHES[source](env), f"built-in coach '{source}'"
    if env.command_gen.reference_time_s() is None:
        # walk: the artifact solved one commanded walk, the task draws random commands, so
        # there is no time along the artifact to follow; its eta0 still sets the bounds
        return COACHES["posture"](env), (
            f"eta0 of the oracle artifact {source}; coach: built-in 'posture' (task "
            f"'{env.task.name}' has no time-indexed reference for the artifact's coach)"
        )
    return (
        ArtifactCoach(source),
        f"coach and eta0 of the oracle artifact {source} (as needed: banded)",
    )


def warm_start(cfg: TrainConfig, env: G1VecEnv, actor: Any, learner_env: Any) -> dict[str, Any]:
    """Before PPO: ``--warmstart-motion`` clones the motion head of ``actor`` from the task's
    reference (stepping ``learner_env``, the env as the learner sees it), then ``--warmstart``
    distils the coach into the assist head (in the states the cloned motion policy visits). The
    report of each goes into ``warmstart.json``."""
    report: dict[str, Any] = {}
    if cfg.warmstart_motion:
        report["motion"] = distill_motion_head(actor, learner_env, cfg.distill)
    if cfg.warmstart:
        coach, source = choose_coach(cfg.warmstart, env)
        report.update(coach=source, **distill_assist_head(actor, env, coach, cfg.distill))
    return report
