"""Evaluation of a run's motion policy with assistance off (``a2cf-mb eval RUN_DIR``)."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner

from optimal_control.files import atomic_write_json
from rl.agents.models import ASSIST_ACTION_DIM
from rl.agents.modes import MotionOnlyEnv, get_mode
from rl.envs.vec_env import G1VecEnv
from rl.runner import (
    CHECKPOINT_DIR,
    LAST_CHECKPOINT,
    POLICY_FILE,
    load_run_config,
    resolve_task,
    rsl_rl_config,
)


@dataclass(frozen=True)
class EvalConfig:
    """Roll out a run's motion policy without assistance (``a2cf-mb eval RUN_DIR``)."""

    num_envs: int = 16  # parallel environments [-]
    num_steps: int = 0  # control steps to roll out; 0: one full episode length [-]
    seed: int = 1  # env seed (differs from training's default 0) [-]
    use_onnx: bool = True  # run the exported policy.onnx (else the last checkpoint's actor) [-]
    video: str = ""  # mp4 of env 0's first episode (needs MUJOCO_GL=egl); empty: no video [-]
    sim2sim: bool = False  # also roll the ONNX policy out in the second simulator (rl.sim2sim)

    def __post_init__(self) -> None:
        if self.num_envs < 1:
            raise ValueError(f"eval num_envs must be >= 1, got {self.num_envs}")
        if self.num_steps < 0:
            raise ValueError(
                f"eval num_steps must be >= 0 (0: one full episode), got {self.num_steps}"
            )


def evaluate(run_dir: str | Path, cfg: EvalConfig = EvalConfig()) -> dict[str, Any]:
    """Roll out the motion policy of ``run_dir`` with assistance off; survival and return.

    Each env's *first* episode is scored: its return (sum of rewards until it ends or the rollout
    stops) and whether it survived (time-out or still running at the end, not a termination).
    A task with an ``evaluation`` config adds its own metrics (``task_metrics``): its evaluator's
    ``on_step(env, active, dones, extras)`` runs after every step (``active`` (N,) bool: the env is
    still in its first episode, before this step) and ``finish(run_dir) -> dict`` at the end (it
    may write plots into ``run_dir``).
    The result is also written to ``RUN_DIR/eval.json``.
    """
    from rl.export import OnnxMotionPolicy

    run_dir = Path(run_dir)
    train_cfg = load_run_config(run_dir)
    env_cfg = dataclasses.replace(train_cfg.env, num_envs=cfg.num_envs, seed=cfg.seed)
    env = G1VecEnv(env_cfg, resolve_task(train_cfg))
    env.set_assist_enabled(False)
    env.set_less_assist_reward(False)
    motion_dim = env.num_actions - ASSIST_ACTION_DIM
    if cfg.use_onnx:
        onnx_policy = OnnxMotionPolicy(run_dir / POLICY_FILE)

        def policy(obs: Any) -> torch.Tensor:
            return torch.from_numpy(
                onnx_policy(obs["policy"].cpu().numpy(), obs["history"].cpu().numpy())
            )

    else:
        mode = get_mode(train_cfg.mode)
        learner_env: VecEnv = env if mode.assist else MotionOnlyEnv(env)
        with contextlib.redirect_stdout(io.StringIO()):
            runner = OnPolicyRunner(learner_env, rsl_rl_config(train_cfg, mode), log_dir=None)
        state = torch.load(run_dir / CHECKPOINT_DIR / LAST_CHECKPOINT, weights_only=False)
        runner.alg.load(state, {"actor": True}, strict=True)
        torch_policy = runner.alg.get_policy().motion_policy().eval()

        def policy(obs: Any) -> torch.Tensor:
            return torch_policy(obs["policy"], obs["history"])

    num_steps = cfg.num_steps or int(env.max_episode_length)
    evaluator = env.task.evaluation.build(env) if env.task.evaluation is not None else None
    returns = torch.zeros(cfg.num_envs)
    lengths = torch.zeros(cfg.num_envs)
    active = torch.ones(cfg.num_envs, dtype=torch.bool)
    fell = torch.zeros(cfg.num_envs, dtype=torch.bool)
    obs = env.get_observations()
    zeros = torch.zeros(cfg.num_envs, ASSIST_ACTION_DIM)
    qpos_env0 = [env.state[0, env.layout.qpos].copy()] if cfg.video else []
    with torch.inference_mode(), contextlib.closing(env):
        for _ in range(num_steps):
            actions = policy(obs).reshape(cfg.num_envs, motion_dim)
            obs, rewards, dones, extras = env.step(torch.cat([actions, zeros], dim=-1))
            if cfg.video and active[0] and not bool(dones[0]):
                qpos_env0.append(env.state[0, env.layout.qpos].copy())
            if evaluator is not None:
                evaluator.on_step(env, active, dones, extras)
            returns += torch.where(active, rewards.float().cpu(), 0.0)
            lengths += active.float()
            done = dones.bool().cpu()
            time_out = extras["time_outs"].bool().cpu()
            fell |= active & done & ~time_out
            active &= ~done
            if not active.any():
                break
    result = {
        "run_dir": str(run_dir),
        "task": train_cfg.task,
        "mode": train_cfg.mode,
        "policy": "onnx" if cfg.use_onnx else "checkpoint",
        "num_envs": cfg.num_envs,
        "num_steps": num_steps,
        "survival_fraction": float((~fell).float().mean()),
        "mean_return": float(returns.mean()),
        "mean_episode_length_steps": float(lengths.mean()),
    }
    if evaluator is not None:
        result["task_metrics"] = evaluator.finish(run_dir)
    if cfg.sim2sim:
        from rl.sim2sim import Sim2SimConfig, run_sim2sim

        result["sim2sim"] = run_sim2sim(
            run_dir, env.task, num_steps, Sim2SimConfig(num_envs=cfg.num_envs, seed=cfg.seed)
        )
    if cfg.video:
        from optimal_control.render import RenderUnavailableError

        try:
            result["video"] = str(
                _render_qpos(np.asarray(qpos_env0), env.step_dt_s, cfg.video, train_cfg.task)
            )
        except RenderUnavailableError as err:  # no GL / no encoder: the metrics still count
            result["video_note"] = f"no video: {err}"
            warnings.warn(f"eval: {result['video_note']}", stacklevel=2)
    atomic_write_json(run_dir / "eval.json", result)
    return result


def _render_qpos(qpos: np.ndarray, dt_s: float, path: str, name: str) -> Path:
    """Kinematic replay video of MuJoCo configurations (T, 36) with the full visual G1 model."""
    from optimal_control.reference import Reference
    from optimal_control.render import render_reference
    from robots.conventions import mj_to_pin_q

    q = np.stack([mj_to_pin_q(row) for row in qpos])
    frames = q.shape[0]
    ref = Reference(
        time_s=np.arange(frames) * dt_s,
        q=q,
        v=np.zeros((frames, q.shape[1] - 1)),
        a=np.zeros((frames, q.shape[1] - 1)),
        contacts=np.zeros((frames, 2), dtype=bool),
        phase=np.zeros(frames, dtype=int),
        phase_names=(name,),
        dt=dt_s,
        name=name,
    )
    return render_reference(ref, path)
