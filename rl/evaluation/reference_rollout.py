"""Controllers played along a task's whole reference, from its first frame, in the training env,
with every step's joint pose recorded: how a learned policy (assistance off) and the oracle's own
motion (its reference held by the joint PD, with or without its coach's pelvis wrench) track the
same reference on the same randomised robots.

The training evaluations (:mod:`rl.evaluation.alone`) start each episode on a random frame and keep
scores only; here every episode starts on the clip's first frame and lasts the whole clip, so the
joint traces of different controllers line up in time and can be drawn over the reference. The
scores come from the task's own evaluator (for the dance, :class:`rl.tasks.dance.DanceEvaluator`),
so they mean what ``a2cf-mb eval`` and ``evals.jsonl`` mean. Used by
``docs/notebooks/optimisation_vs_rl.ipynb``.
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict

from rl.envs.config import EnvConfig
from rl.envs.task_schema import TaskConfig
from rl.envs.vec_env import G1VecEnv
from rl.runs.folder import CHECKPOINT_DIR, POLICY_FILE, load_run_config
from robots import g1

MotionFn = Callable[[G1VecEnv, TensorDict], torch.Tensor]
"""``motion(env, obs) -> motion actions (N, 29)`` (joint target = stand + scale * action)."""
AssistFn = Callable[[G1VecEnv], torch.Tensor]
"""``assist(env) -> pelvis wrench (N, 6) [N, N m]`` in the assist action's heading frame."""

_MAX_BOUND_FRACTION = 0.999  # atanh stays finite: a wrench is played up to 99.9 % of its bound


@dataclass(frozen=True)
class ReferenceRolloutConfig:
    """The robots a controller is played on: one episode each along the whole reference."""

    num_envs: int = 16  # randomised robots (friction, payload, CoM; observation noise) [-]
    seed: int = 10_000  # env seed, the evaluations': every controller meets the same robots [-]
    num_threads: int = 1  # physics threads [-]

    def __post_init__(self) -> None:
        if self.num_envs < 1 or self.num_threads < 0:
            raise ValueError(
                f"ReferenceRolloutConfig: num_envs must be >= 1 and num_threads >= 0, got "
                f"{self.num_envs}, {self.num_threads}"
            )


@dataclass
class ReferenceRollout:
    """What one controller did along the reference (T recorded steps, N robots).

    ``time_s`` (T,): time along the reference of the state after each step [s];
    ``joint_pos_rad`` / ``ref_joint_pos_rad`` (T, N, 29): joint pose reached and the reference's
    at that time [rad] (joint order of :data:`robots.g1.JOINT_NAMES`); ``alive`` (T, N): the robot
    is still in its first episode after the step (traces past a fall are not its own: masked);
    ``applied_wrench`` (T, N, 6): the pelvis wrench applied during the step, heading frame
    [N, N m]; ``metrics``: ``survival_fraction`` and the task evaluator's scores.
    """

    label: str
    time_s: np.ndarray
    joint_pos_rad: np.ndarray
    ref_joint_pos_rad: np.ndarray
    alive: np.ndarray
    applied_wrench: np.ndarray
    metrics: dict[str, Any]

    def joint(self, name: str, env: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(time [s], angle [rad]) of joint ``name`` on robot ``env`` while it was alive."""
        j = g1.JOINT_NAMES.index(name)
        keep = self.alive[:, env]
        return self.time_s[keep], self.joint_pos_rad[keep, env, j]

    def error_per_part_rad(self) -> dict[str, float]:
        """Mean |q - q_ref| per body part (:data:`robots.g1.BODY_PARTS`) and ``all`` over the
        alive steps [rad] (the evaluator's ``joint_<part>_rad``, recomputed from the traces)."""
        err = np.abs(self.joint_pos_rad - self.ref_joint_pos_rad)[self.alive]  # (K, 29)
        if err.size == 0:
            return {part: float("nan") for part in (*g1.BODY_PARTS, "all")}
        out = {part: float(err[:, idx].mean()) for part, idx in g1.BODY_PARTS.items()}
        out["all"] = float(err.mean())
        return out


def whole_clip_task(task: TaskConfig) -> TaskConfig:
    """``task`` (a clip-tracking task: the dance) with every episode starting on the first frame
    of a clip and lasting as long as the longest clip: the start frame is drawn in
    ``[0, length - min_frames_left)``, so ``min_frames_left`` = the clip's length pins it to 0."""
    from rl.tasks.dance.clips import clip_library
    from rl.tasks.dance.command import ClipTrackingConfig

    if not isinstance(task.commands, ClipTrackingConfig):
        raise ValueError(
            f"task '{task.name}' does not track clips (its command is "
            f"{type(task.commands).__name__}): whole-clip rollouts need a clip-tracking task such "
            "as dance-joints"
        )
    lib = clip_library(task.commands.sources, task.commands.step_dt_s)
    frames = int(lib.length.max())
    return dataclasses.replace(
        task,
        # frames - 1 steps; half a step less so the env's ceil(length / dt) cannot round up
        episode_length_s=(frames - 1.5) * task.commands.step_dt_s,
        commands=dataclasses.replace(task.commands, min_frames_left=frames),
    )


def build_env(
    task: TaskConfig,
    env_cfg: EnvConfig = EnvConfig(),
    cfg: ReferenceRolloutConfig = ReferenceRolloutConfig(),
) -> G1VecEnv:
    """An env of ``task`` along whole clips (:func:`whole_clip_task`), ``env_cfg`` (a run's, for its
    policy's observations) resized to ``cfg``'s robots and seed."""
    env_cfg = dataclasses.replace(
        env_cfg, num_envs=cfg.num_envs, seed=cfg.seed, num_threads=cfg.num_threads
    )
    return G1VecEnv(env_cfg, whole_clip_task(task))


def reference_motion(env: G1VecEnv, obs: TensorDict) -> torch.Tensor:
    """The oracle's motion: the joint PD target is the reference's next pose (no feedback beyond
    the PD, no feed-forward torque: the env's action is a joint target)."""
    return env.joint_targets_to_actions(env.command_gen.reference_joint_pos_rad())


def learned_motion(run_dir: str | Path, env: G1VecEnv) -> tuple[MotionFn, str]:
    """The deterministic motion policy of a run folder and what it is: ``policy.onnx`` when the
    run has finished, else its newest kept checkpoint ``checkpoints/model_<k>.pt`` (a run still
    training). Raises FileNotFoundError when the run has neither."""
    run_dir = Path(run_dir)
    onnx = run_dir / POLICY_FILE
    if onnx.is_file():
        from rl.agents.export import OnnxMotionPolicy

        policy = OnnxMotionPolicy(onnx)

        def motion(env: G1VecEnv, obs: TensorDict) -> torch.Tensor:
            return torch.from_numpy(
                policy(obs["policy"].cpu().numpy(), obs["history"].cpu().numpy())
            )

        return motion, POLICY_FILE
    kept = sorted(
        (int(p.stem.split("_")[1]), p) for p in (run_dir / CHECKPOINT_DIR).glob("model_*.pt")
    )
    if not kept:
        raise FileNotFoundError(
            f"{run_dir} has no {POLICY_FILE} and no kept checkpoint ({CHECKPOINT_DIR}/model_<k>"
            ".pt) yet: let the run reach its first save_interval, or drop it from the comparison"
        )
    from rl.evaluation.policy import checkpoint_motion_policy

    iteration, path = kept[-1]
    actor = checkpoint_motion_policy(load_run_config(run_dir), env, path)
    return (lambda env, obs: actor(obs["policy"], obs["history"])), f"checkpoint {iteration}"


def coach_assist(artifact: str | Path) -> AssistFn:
    """The oracle artifact's coach, always on (no tolerance band): its per-frame wrench plus PD on
    the pelvis pose, at each robot's time along the reference, clipped to the env's bound."""
    from rl.a2cf.coaches import ArtifactCoach, ArtifactCoachConfig

    return ArtifactCoach(str(artifact), ArtifactCoachConfig(band_position_m=0.0,
                                                            band_orientation_rad=0.0))  # fmt: skip


def rollout_reference(
    env: G1VecEnv,
    motion: MotionFn,
    assist: AssistFn | None = None,
    assist_bound: torch.Tensor | np.ndarray | None = None,
    label: str = "",
) -> ReferenceRollout:
    """Play ``motion`` (and ``assist``'s pelvis wrench, else none) for one episode of every env.

    Args:
        env: an env of a task with a time-indexed joint reference (:func:`build_env`); it is reset.
        motion: the motion actions (:func:`learned_motion`, :func:`reference_motion`).
        assist: the wrench to apply (:func:`coach_assist`); None: assistance off, as the
            evaluations of a policy alone.
        assist_bound: (num_phases, 6) [N, N m] bound of the wrench (the oracle's eta0); needed
            with ``assist``. No random mask.
        label: the name the rollout carries (plots, tables).

    The task's evaluator draws its figure into a temporary folder; the dance's selects
    matplotlib's Agg backend to do so (a notebook then displays its figures as images).
    """
    if env.command_gen.reference_joint_pos_rad() is None:
        raise ValueError(
            f"task '{env.task.name}' has no time-indexed joint reference (its command gives no "
            "reference_joint_pos_rad): reference rollouts need one (dance)"
        )
    if assist is not None and assist_bound is None:
        raise ValueError("rollout_reference: an assist needs its bound (assist_bound, eta0)")
    env.for_evaluation()
    env.set_less_assist_reward(False)
    env.set_random_mask_prob(0.0)
    env.set_assist_enabled(assist is not None)
    if assist is not None:
        env.set_assist_bound(torch.as_tensor(np.asarray(assist_bound), dtype=torch.float32))
    n = env.num_envs
    obs = env.reset_envs(torch.arange(n))
    if env.command_gen.reference_time_s().abs().max() > 1e-9:
        raise ValueError(
            "rollout_reference: the env's episodes do not start on the reference's first frame, so "
            "the traces of different robots would not line up: build it with build_env"
        )
    evaluator = env.task.evaluation.build(env) if env.task.evaluation is not None else None
    active = torch.ones(n, dtype=torch.bool)
    fell = torch.zeros(n, dtype=torch.bool)
    q, q_ref, alive, wrench = [], [], [], []
    nj = g1.NUM_JOINTS
    with torch.no_grad():  # not inference_mode: the env's buffers stay usable after it
        for _ in range(int(env.max_episode_length)):
            target = env.command_gen.reference_joint_pos_rad().clone()  # for the state after
            actions = torch.zeros(n, env.num_actions)
            actions[:, :nj] = motion(env, obs).reshape(n, nj)
            if assist is not None:
                bound = env.env_state.assist_bound.clamp_min(1e-9)
                ratio = (assist(env) / bound).clamp(-_MAX_BOUND_FRACTION, _MAX_BOUND_FRACTION)
                actions[:, nj:] = torch.atanh(ratio)
            obs, _, dones, extras = env.step(actions)
            if evaluator is not None:
                evaluator.on_step(env, active, dones, extras)
            done = dones.bool().cpu()  # the traces and these flags are kept on the host
            fell |= active & done & ~extras["time_outs"].bool().cpu()
            active &= ~done
            q.append(env.env_state.joint_pos_rad.cpu().numpy().copy())
            q_ref.append(target.cpu().numpy())
            alive.append(active.cpu().numpy().copy())
            wrench.append(env.applied_wrench.cpu().numpy().copy())
            if not active.any():
                break
    metrics: dict[str, Any] = {"survival_fraction": float((~fell).float().mean())}
    if evaluator is not None:
        with tempfile.TemporaryDirectory() as tmp:
            scores = evaluator.finish(tmp)
        scores.pop("plot", None)
        metrics.update({k: v.item() if hasattr(v, "item") else v for k, v in scores.items()})
    return ReferenceRollout(
        label=label,
        time_s=np.arange(1, len(q) + 1) * env.step_dt_s,  # every robot started on frame 0
        joint_pos_rad=np.asarray(q),
        ref_joint_pos_rad=np.asarray(q_ref),
        alive=np.asarray(alive),
        applied_wrench=np.asarray(wrench),
        metrics=metrics,
    )
