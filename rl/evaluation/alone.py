"""The motion policy alone: one episode per fresh env, assistance off, scored against the task's
skill target. Shared by ``a2cf-mb eval`` (:func:`rl.evaluation.policy.evaluate`), the evaluations during
training (every ``eval_interval`` iterations, :class:`AloneEvaluation`) and ``a2cf-mb eval-curve``
(the kept checkpoints of a finished run).

What the curriculum, the skill measure and A2CF's helped episodes say is about the *helped* robot;
whether a skill is learned is judged here only: fresh envs (their own seed), no wrench, the
task's command curriculum at its final ranges, each env's first episode.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict

from optimal_control.files import atomic_write_text
from rl.agents.models import ASSIST_ACTION_DIM
from rl.envs.config import EnvConfig
from rl.envs.task_schema import TaskConfig
from rl.envs.vec_env import G1VecEnv
from rl.evaluation.config import AloneEvalConfig
from rl.runs.folder import EVALS_DIR, EVALS_LOG

MotionPolicyFn = Callable[[TensorDict], torch.Tensor]
"""``policy(obs) -> motion actions (N, 29)`` from the env's observation groups."""


def rollout_alone(
    env: G1VecEnv,
    policy: MotionPolicyFn,
    num_steps: int = 0,
    out_dir: str | Path | None = None,
    on_step: Callable[[G1VecEnv], None] | None = None,
) -> dict[str, Any]:
    """Roll ``policy`` out on ``env`` with assistance off and score each env's first episode.

    ``on_step(env)`` sees every frame of env 0's first episode (a video's frames).
    ``num_steps`` 0: one full episode length. A task with an ``evaluation`` config adds
    ``task_metrics`` (its evaluator may write figures into ``out_dir``). Returns survival share,
    mean return and episode length, whether the task's target is reached, and the task metrics.
    """
    env.for_evaluation()
    env.set_assist_enabled(False)
    env.set_less_assist_reward(False)
    n = env.num_envs
    env.reset_envs(torch.arange(n, device=env.device))
    task = env.task
    evaluator = task.evaluation.build(env) if task.evaluation is not None else None
    num_steps = num_steps or int(env.max_episode_length)
    returns = torch.zeros(n)
    lengths = torch.zeros(n)
    active = torch.ones(n, dtype=torch.bool)
    fell = torch.zeros(n, dtype=torch.bool)
    obs = env.get_observations()
    if on_step is not None:
        on_step(env)  # the first frame of env 0's episode
    zeros = torch.zeros(n, ASSIST_ACTION_DIM, device=env.device)
    with torch.inference_mode():
        for _ in range(num_steps):
            actions = policy(obs).reshape(n, env.num_actions - ASSIST_ACTION_DIM).to(env.device)
            obs, rewards, dones, extras = env.step(torch.cat([actions, zeros], dim=-1))
            if on_step is not None and active[0] and not bool(dones[0]):
                on_step(env)
            if evaluator is not None:
                evaluator.on_step(env, active, dones, extras)
            returns += torch.where(active, rewards.float().cpu(), 0.0)
            lengths += active.float()
            done = dones.bool().cpu()
            fell |= active & done & ~extras["time_outs"].bool().cpu()
            active &= ~done
            if not active.any():
                break
    result: dict[str, Any] = {
        "num_envs": n,
        "num_steps": num_steps,
        "survival_fraction": float((~fell).float().mean()),
        "mean_return": float(returns.mean()),
        "mean_episode_length_steps": float(lengths.mean()),
    }
    if evaluator is not None:
        folder = Path(out_dir) if out_dir is not None else None
        if folder is None:
            import tempfile

            with tempfile.TemporaryDirectory() as tmp:
                result["task_metrics"] = _json_ready(evaluator.finish(tmp))
                result["task_metrics"].pop("plot", None)
        else:
            folder.mkdir(parents=True, exist_ok=True)
            result["task_metrics"] = _json_ready(evaluator.finish(folder))
    result["target"] = task.target.describe()
    result["target_reached"] = task.target.reached(result)
    result["target_progress"] = task.target.progress(result)
    return result


def _json_ready(metrics: dict[str, Any]) -> dict[str, Any]:
    return json.loads(
        json.dumps(metrics, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    )


class AloneEvaluation:
    """Evaluations of a training run's motion policy alone, every ``cfg.interval`` iterations.

    Each evaluation builds fresh envs from the same seed, so the scores of two iterations (and of
    two runs of one task) are measured on the same episodes. It draws from its own generators only:
    training after it is bit-identical to training without it.
    """

    def __init__(
        self, task: TaskConfig, env_cfg: EnvConfig, cfg: AloneEvalConfig, run_dir: Path
    ) -> None:
        self.task = task
        self.env_cfg = dataclasses.replace(env_cfg, num_envs=cfg.num_envs, seed=cfg.seed)
        self.cfg = cfg
        self.run_dir = run_dir
        self.rows: list[dict[str, Any]] = []

    def due(self, completed: int, total: int) -> bool:
        """Whether an evaluation runs after ``completed`` of ``total`` iterations."""
        interval = self.cfg.interval
        return interval > 0 and (completed % interval == 0 or completed == total)

    def __call__(self, policy: torch.nn.Module, iteration: int, env_steps: int) -> dict[str, Any]:
        """Evaluate ``policy`` (a :class:`rl.agents.models.MotionPolicy`); returns and keeps the
        row (iteration, env steps, the scores)."""
        policy = policy.eval()
        env = G1VecEnv(self.env_cfg, self.task)
        try:
            result = rollout_alone(
                env,
                lambda obs: policy(obs["policy"], obs["history"]),
                out_dir=self.run_dir / EVALS_DIR,
            )
        finally:
            env.close()
        row = {"iteration": iteration, "env_steps": env_steps, **result}
        self.rows = [r for r in self.rows if r["iteration"] < iteration] + [row]
        return row

    def write(self) -> None:
        """``evals.jsonl``: the rows so far (rewritten whole, so it always matches the checkpoint)."""
        text = "".join(json.dumps(r) + "\n" for r in self.rows)
        atomic_write_text(self.run_dir / EVALS_LOG, text)

    def first_held(self) -> dict[str, Any] | None:
        """The first row from which the task's target held at two consecutive evaluations
        (None: not yet); see :func:`target_held`."""
        return target_held(self.rows)

    @staticmethod
    def scalars(row: dict[str, Any]) -> dict[str, float]:
        """TensorBoard scalars of a row: ``Eval/survival``, ``Eval/<task metric>``, ..."""
        out = {
            "Eval/survival": row["survival_fraction"],
            "Eval/mean_return": row["mean_return"],
            "Eval/episode_length": row["mean_episode_length_steps"],
            "Eval/target_reached": float(row["target_reached"]),
        }
        for key, value in row.get("task_metrics", {}).items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                out[f"Eval/{key}"] = float(value)
        return out


def target_held(rows: list[dict[str, Any]], times: int = 2) -> dict[str, Any] | None:
    """The first evaluation row from which the target held at ``times`` consecutive evaluations
    (the judge of a learning claim: one 32-env evaluation reaching it is one noisy draw of many)."""
    for i in range(len(rows) - times + 1):
        if all(r["target_reached"] for r in rows[i : i + times]):
            return rows[i]
    return None


def first_reached_once(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The first evaluation row that reached the target: one draw, not a claim (:func:`target_held`)."""
    return next((r for r in rows if r["target_reached"]), None)


def curve_arrays(rows: list[dict[str, Any]], metric: str) -> tuple[np.ndarray, np.ndarray]:
    """(env steps, values) of ``metric`` (``survival_fraction`` or a task metric) over ``rows``."""
    steps, values = [], []
    for row in rows:
        value = row.get(metric, row.get("task_metrics", {}).get(metric))
        if value is not None:
            steps.append(row["env_steps"])
            values.append(float(value))
    return np.asarray(steps), np.asarray(values)
