"""Training runs: typed configs, the run folder, the A2CF training loop, checkpoints and resume.

:func:`train` is the one entry point (``a2cf-mb train`` calls it). A run folder holds::

    config.json          resolved TrainConfig, env config and the rsl-rl runner config
    git.json             git revision and dirty flag of the project
    git/                 rsl-rl's git diff of the code state
    events.out.tfevents* TensorBoard scalars (rsl-rl logger + Curriculum/*, Train/mean_step_reward)
    checkpoints/         last.pt (every iteration, atomic) and model_<iteration>.pt
    curriculum.jsonl     one line per iteration: bounds, applied wrench, switches
    metrics.json         per-iteration figures and the run summary
    policy.onnx          exported motion policy (+ policy.json describing its inputs/outputs)

The loop is rsl-rl's :class:`~rsl_rl.runners.OnPolicyRunner` (same algorithm construction, logger,
act/process_env_step/compute_returns/update sequence) with the A2CF curriculum between iterations.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import random
import subprocess
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils import check_nan

from rl.agents.models import ASSIST_ACTION_DIM
from rl.agents.modes import ModeSpec, MotionOnlyEnv, get_mode
from rl.curriculum import (
    PAPER_INITIAL_BOUNDS,
    WRENCH_AXES,
    AssistCurriculum,
    AssistStatistics,
    CurriculumConfig,
    CurriculumUpdate,
    identical_axis_bounds,
    paper_initial_bounds,
)

CONFIG_FILE = "config.json"
CHECKPOINT_DIR = "checkpoints"
LAST_CHECKPOINT = "last.pt"
CURRICULUM_LOG = "curriculum.jsonl"
METRICS_FILE = "metrics.json"
POLICY_FILE = "policy.onnx"


@dataclass(frozen=True)
class PPOConfig:
    """rsl-rl PPO hyper-parameters (rsl-rl / legged-gym defaults)."""

    learning_rate: float = 1e-3  # initial Adam learning rate (adaptive schedule) [-]
    num_learning_epochs: int = 5  # passes over each rollout [-]
    num_mini_batches: int = 4  # mini-batches per pass [-]
    clip_param: float = 0.2  # PPO ratio clip [-]
    gamma: float = 0.99  # discount per control step [-]
    lam: float = 0.95  # GAE lambda [-]
    value_loss_coef: float = 1.0  # weight of the value loss [-]
    entropy_coef: float = 0.005  # weight of the entropy bonus [-]
    max_grad_norm: float = 1.0  # gradient-norm clip [-]
    desired_kl: float = 0.01  # target KL of the adaptive learning-rate schedule [-]
    init_noise_std: float = 0.5  # initial std of the motion actions (raw action units) [-]
    assist_init_noise_std: float = 1.0  # initial std of the raw assist actions (before tanh) [-]


@dataclass(frozen=True)
class ModelConfig:
    """Network sizes and the VAE loss weights."""

    motion_hidden_dims: tuple[int, ...] = (256, 128, 64)  # motion-head hidden layers [-]
    assist_hidden_dims: tuple[int, ...] = (128, 64)  # assist-head hidden layers [-]
    critic_hidden_dims: tuple[int, ...] = (256, 128, 64)  # critic hidden layers [-]
    encoder_hidden_dims: tuple[int, ...] = (128, 64)  # VAE encoder hidden layers [-]
    latent_dim: int = 16  # VAE latent size [-]
    activation: str = "elu"  # activation of every MLP [-]
    vae_learning_rate: float = 1e-3  # Adam learning rate of the history encoder [-]
    vae_kl_weight: float = 1e-3  # beta of the beta-VAE [-]
    vae_velocity_weight: float = 1.0  # weight of the velocity-estimation loss [-]


@dataclass(frozen=True)
class TrainConfig:
    """One training run (``a2cf-mb train``); the nested configs get ``--ppo-*``, ``--model-*`` and
    ``--curriculum-*`` flags."""

    task: str = "stand"  # task name from rl.tasks.TASKS [-]
    mode: str = "a2cf"  # baseline | a2cf | no-pi | no-id | no-rm [-]
    num_envs: int = 64  # parallel environments [-]
    iterations: int = 100  # total learning iterations of the run (a resume continues up to it) [-]
    num_steps_per_env: int = 24  # control steps per env per iteration (rollout length) [-]
    seed: int = 0  # seed of torch, numpy, random [-]
    out: str = "runs"  # parent folder of new run folders [-]
    run_name: str = ""  # run folder name; empty: <task>_<mode>_<UTC time> [-]
    resume: str = ""  # run folder to continue from its last checkpoint; empty: new run [-]
    save_interval: int = 50  # iterations between kept checkpoints model_<it>.pt [-]
    random_mask_prob: float = 0.2  # zeta, probability of dropping a wrench component [-]
    device: str = "cpu"  # torch device of the learner [-]
    export_onnx: bool = True  # export the motion policy to ONNX at the end [-]
    random_episode_start: bool = True  # random initial episode counters (spread time-outs) [-]
    ppo: PPOConfig = field(default_factory=PPOConfig)  # PPO hyper-parameters
    model: ModelConfig = field(default_factory=ModelConfig)  # network sizes and VAE weights
    curriculum: CurriculumConfig = field(default_factory=CurriculumConfig)  # Algorithm 1

    def __post_init__(self) -> None:
        """Check values a user could get wrong."""
        get_mode(self.mode)
        for name in ("num_envs", "iterations", "num_steps_per_env", "save_interval"):
            if getattr(self, name) <= 0:
                raise ValueError(f"train config '{name}' must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.random_mask_prob < 1.0:
            raise ValueError(f"random_mask_prob must be in [0, 1), got {self.random_mask_prob}")
        if (self.num_envs * self.num_steps_per_env) < self.ppo.num_mini_batches:
            raise ValueError(
                f"num_envs * num_steps_per_env = {self.num_envs * self.num_steps_per_env} is smaller "
                f"than ppo.num_mini_batches = {self.ppo.num_mini_batches}"
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dictionary."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict` (lists back to tuples)."""

        def build(kind: type, values: dict[str, Any]) -> Any:
            kwargs = {}
            for f in dataclasses.fields(kind):
                if f.name not in values:
                    continue
                value = values[f.name]
                if isinstance(value, list):
                    value = tuple(value)
                kwargs[f.name] = value
            return kind(**kwargs)

        data = dict(data)
        nested = {
            "ppo": build(PPOConfig, data.pop("ppo", {})),
            "model": build(ModelConfig, data.pop("model", {})),
            "curriculum": build(CurriculumConfig, data.pop("curriculum", {})),
        }
        return dataclasses.replace(build(cls, data), **nested)


@dataclass
class TrainResult:
    """What :func:`train` returns."""

    run_dir: Path  # the run folder
    iterations_done: int  # learning iterations completed in the run so far
    metrics: dict[str, Any]  # the content of metrics.json


def rsl_rl_config(cfg: TrainConfig, mode: ModeSpec) -> dict[str, Any]:
    """The rsl-rl runner configuration (class names, obs_groups, PPO and model kwargs)."""
    actor_groups = ["policy", "history"] + (
        ["privileged"] if mode.assist and mode.assist_privileged else []
    )
    ppo = asdict(cfg.ppo)
    init_noise_std = ppo.pop("init_noise_std")
    assist_init_std = ppo.pop("assist_init_noise_std")
    return {
        "num_steps_per_env": cfg.num_steps_per_env,
        "save_interval": cfg.save_interval,
        "obs_groups": {"actor": actor_groups, "critic": ["critic"]},
        "algorithm": {
            "class_name": "rl.agents.ppo:A2CFPPO",
            **ppo,
            "schedule": "adaptive",
            "vae_learning_rate": cfg.model.vae_learning_rate,
            "vae_kl_weight": cfg.model.vae_kl_weight,
            "vae_velocity_weight": cfg.model.vae_velocity_weight,
        },
        "actor": {
            "class_name": "rl.agents.models:A2CFActor",
            "latent_dim": cfg.model.latent_dim,
            "encoder_hidden_dims": list(cfg.model.encoder_hidden_dims),
            "motion_hidden_dims": list(cfg.model.motion_hidden_dims),
            "assist_hidden_dims": list(cfg.model.assist_hidden_dims),
            "activation": cfg.model.activation,
            "obs_normalization": True,
            "assist_privileged": mode.assist_privileged,
            "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": init_noise_std},
            "assist_init_std": assist_init_std if mode.assist else None,
        },
        "critic": {
            "class_name": "MLPModel",
            "hidden_dims": list(cfg.model.critic_hidden_dims),
            "activation": cfg.model.activation,
            "obs_normalization": True,
        },
        "logger": "tensorboard",
        "check_for_nan": True,
    }


class A2CFRunner(OnPolicyRunner):
    """rsl-rl's on-policy runner with the A2CF curriculum, richer logging and exact resume.

    ``current_learning_iteration`` counts *completed* iterations (rsl-rl stores the last index and
    repeats it on resume; here a resume starts with the first iteration not yet done).
    """

    def __init__(
        self,
        env: VecEnv,
        train_cfg: dict[str, Any],
        run_dir: Path,
        mode: ModeSpec,
        curriculum: AssistCurriculum,
        device: str = "cpu",
    ) -> None:
        """Build algorithm and logger (rsl-rl) and the curriculum bookkeeping."""
        super().__init__(env, train_cfg, log_dir=str(run_dir), device=device)
        self.run_dir = run_dir
        self.mode = mode
        self.curriculum = curriculum
        self.assist_stats = AssistStatistics(curriculum.num_phases)
        self.history: list[dict[str, Any]] = []
        self.apply_curriculum()

    # -- curriculum ---------------------------------------------------------------------------

    def apply_curriculum(self) -> None:
        """Push the curriculum state (bounds, switches) and the mode to the env."""
        env = self.env
        if self.mode.assist:
            env.set_assist_bound(self.curriculum.eta.to(env.device))
            env.set_assist_enabled(self.curriculum.assist_enabled)
            env.set_less_assist_reward(self.curriculum.less_assist_reward)
        else:
            env.set_assist_enabled(False)
            env.set_less_assist_reward(False)

    # -- training loop ------------------------------------------------------------------------

    def learn(self, num_learning_iterations: int, init_at_random_ep_len: bool = False) -> None:
        """Run ``num_learning_iterations`` iterations of rollout, PPO+VAE update and curriculum."""
        if init_at_random_ep_len:
            self.env.episode_length_buf = torch.randint_like(
                self.env.episode_length_buf, high=int(self.env.max_episode_length)
            )
        obs = self.env.get_observations().to(self.device)
        self.alg.train_mode()
        self.logger.init_logging_writer()
        writer = self.logger.writer
        start_it = self.current_learning_iteration
        total_it = start_it + num_learning_iterations
        num_steps = self.cfg["num_steps_per_env"]
        for it in range(start_it, total_it):
            self.apply_curriculum()
            self.assist_stats.reset()
            reward_sum = 0.0
            skill_sum = 0.0
            start = time.time()
            with torch.inference_mode():
                for _ in range(num_steps):
                    actions = self.alg.act(obs)
                    obs, rewards, dones, extras = self.env.step(actions.to(self.env.device))
                    check_nan(obs, rewards, dones)
                    obs, rewards, dones = (
                        obs.to(self.device),
                        rewards.to(self.device),
                        dones.to(self.device),
                    )
                    self.alg.process_env_step(obs, rewards, dones, extras)
                    self.logger.process_env_step(rewards, dones, extras, None)
                    reward_sum += float(rewards.float().mean())
                    skill_sum += float(extras.get("skill_progress", 0.0))
                    if self.mode.assist and self.curriculum.assist_enabled:
                        self.assist_stats.add(extras["assist"])
                collect_time = time.time() - start
                start = time.time()
                self.alg.compute_returns(obs)
            loss_dict = self.alg.update()
            learn_time = time.time() - start
            self.current_learning_iteration = it + 1

            skill_progress = skill_sum / num_steps
            applied_norm, visited = self.assist_stats.result()
            mean_force_n = self.assist_stats.mean_force_n()
            update: CurriculumUpdate | None = None
            if self.mode.assist:
                update = self.curriculum.update(it, applied_norm, visited, skill_progress)

            self.logger.log(
                it=it,
                start_it=start_it,
                total_it=total_it,
                collect_time=collect_time,
                learn_time=learn_time,
                loss_dict=loss_dict,
                learning_rate=self.alg.learning_rate,
                action_std=self.alg.get_policy().output_std,
                rnd_weight=None,
            )
            row = self._iteration_row(
                it,
                collect_time,
                learn_time,
                reward_sum / num_steps,
                skill_progress,
                mean_force_n,
                loss_dict,
            )
            self.history.append(row)
            if writer is not None:
                self._write_scalars(writer, it, row, update)
            if update is not None:
                with open(self.run_dir / CURRICULUM_LOG, "a", encoding="utf-8") as f:
                    f.write(
                        json.dumps({**update.as_dict(), "applied_force_n": mean_force_n}) + "\n"
                    )
            self.save_checkpoint(
                keep=(it + 1) % self.cfg["save_interval"] == 0 or it + 1 == total_it
            )
        if writer is not None:
            writer.flush()
            self.logger.stop_logging_writer()

    def _iteration_row(
        self,
        it: int,
        collect_time: float,
        learn_time: float,
        mean_step_reward: float,
        skill_progress: float,
        mean_force_n: float,
        loss_dict: dict[str, float],
    ) -> dict[str, Any]:
        rewbuffer = self.logger.rewbuffer
        steps = self.cfg["num_steps_per_env"] * self.env.num_envs
        return {
            "iteration": it,
            "env_steps": steps,
            "collect_time_s": collect_time,
            "learn_time_s": learn_time,
            "iteration_time_s": collect_time + learn_time,
            "collect_steps_per_s": steps / max(collect_time, 1e-9),
            "total_steps_per_s": steps / max(collect_time + learn_time, 1e-9),
            "mean_step_reward": mean_step_reward,
            "mean_episode_return": float(np.mean(rewbuffer)) if len(rewbuffer) else None,
            "mean_episode_length": float(np.mean(self.logger.lenbuffer))
            if len(self.logger.lenbuffer)
            else None,
            "skill_progress": skill_progress,
            "applied_force_n": mean_force_n,
            "eta_norm": torch.linalg.vector_norm(self.curriculum.eta, dim=-1).tolist()
            if self.mode.assist
            else None,
            "assist_enabled": bool(self.mode.assist and self.curriculum.assist_enabled),
            "less_assist_reward": bool(self.mode.assist and self.curriculum.less_assist_reward),
            "losses": dict(loss_dict),
        }

    def _write_scalars(
        self, writer: Any, it: int, row: dict[str, Any], update: CurriculumUpdate | None
    ) -> None:
        writer.add_scalar("Train/mean_step_reward", row["mean_step_reward"], it)
        writer.add_scalar("Perf/collect_steps_per_s", row["collect_steps_per_s"], it)
        writer.add_scalar("Curriculum/skill_progress", row["skill_progress"], it)
        writer.add_scalar("Curriculum/applied_force_n", row["applied_force_n"], it)
        writer.add_scalar("Curriculum/assist_enabled", float(row["assist_enabled"]), it)
        writer.add_scalar("Curriculum/less_assist_reward", float(row["less_assist_reward"]), it)
        if update is None:
            return
        names = list(getattr(self.env.task, "phase_names", range(len(update.eta))))
        for phase, bounds, norm in zip(names, update.eta, update.applied_norm, strict=True):
            for axis, value in zip(WRENCH_AXES, bounds, strict=True):
                writer.add_scalar(f"Curriculum/eta_{phase}_{axis}", value, it)
            writer.add_scalar(f"Curriculum/applied_wrench_norm_{phase}", norm, it)

    # -- checkpoints --------------------------------------------------------------------------

    def save_checkpoint(self, keep: bool) -> Path:
        """Write ``checkpoints/last.pt`` atomically and, when ``keep``, ``model_<iteration>.pt``."""
        state = self.alg.save()
        state["iter"] = self.current_learning_iteration
        state["completed_iterations"] = self.current_learning_iteration
        state["curriculum"] = self.curriculum.state_dict()
        state["logger"] = {
            "tot_timesteps": self.logger.tot_timesteps,
            "tot_time": self.logger.tot_time,
        }
        state["history"] = self.history
        state["torch_rng_state"] = torch.get_rng_state()
        state["infos"] = {"mode": self.mode.name}
        folder = self.run_dir / CHECKPOINT_DIR
        folder.mkdir(parents=True, exist_ok=True)
        tmp = folder / (LAST_CHECKPOINT + ".tmp")
        torch.save(state, tmp)
        os.replace(tmp, folder / LAST_CHECKPOINT)
        if keep:
            torch.save(state, folder / f"model_{self.current_learning_iteration}.pt")
        return folder / LAST_CHECKPOINT

    def load_checkpoint(self, path: Path) -> None:
        """Restore weights, optimisers, iteration counter, curriculum, logger totals, RNG."""
        state = torch.load(path, weights_only=False, map_location=self.device)
        self.alg.load(state, None, strict=True)
        self.current_learning_iteration = int(state["completed_iterations"])
        self.curriculum.load_state_dict(state["curriculum"])
        self.logger.tot_timesteps = state["logger"]["tot_timesteps"]
        self.logger.tot_time = state["logger"]["tot_time"]
        self.history = list(state.get("history", []))
        torch.set_rng_state(state["torch_rng_state"])
        self.apply_curriculum()
        self._truncate_curriculum_log()

    def _truncate_curriculum_log(self) -> None:
        """Drop log lines of iterations after the checkpoint (a kill between log and save)."""
        path = self.run_dir / CURRICULUM_LOG
        if not path.is_file():
            return
        lines = [line for line in path.read_text().splitlines() if line.strip()]
        kept = [
            line
            for line in lines
            if json.loads(line)["iteration"] < self.current_learning_iteration
        ]
        if len(kept) != len(lines):
            path.write_text("".join(line + "\n" for line in kept))


def git_revision(path: Path) -> dict[str, Any]:
    """Git commit and dirty flag of the repository holding ``path`` (None outside git)."""

    def git(*args: str) -> str | None:
        try:
            out = subprocess.run(
                ["git", *args], cwd=path, capture_output=True, text=True, timeout=10, check=True
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return out.stdout.strip()

    commit = git("rev-parse", "HEAD")
    status = git("status", "--porcelain")
    return {"commit": commit, "dirty": bool(status) if status is not None else None}


def seed_everything(seed: int) -> None:
    """Seed python, numpy and torch."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - legacy global RNG, seeded for any code that still uses it
    torch.manual_seed(seed)


def initial_bounds(
    task_name: str,
    num_phases: int,
    mode: ModeSpec,
    eta0: torch.Tensor | None,
    task_default: torch.Tensor,
) -> torch.Tensor:
    """Initial assist bounds (num_phases, 6) [N, Nm].

    Source, first match: ``eta0`` (e.g. an oracle artifact's), the paper's table for the task
    (:data:`rl.curriculum.PAPER_INITIAL_BOUNDS`; "stand" uses the walking row), the task's own
    ``default_assist_bound()``. The ``no-id`` mode then makes x, y, z identical.
    """
    if eta0 is not None:
        bounds = torch.as_tensor(eta0, dtype=torch.float32)
    elif task_name in PAPER_INITIAL_BOUNDS:
        bounds = paper_initial_bounds(task_name, num_phases)
    else:
        bounds = torch.as_tensor(task_default, dtype=torch.float32)
    if bounds.shape != (num_phases, 6):
        raise ValueError(
            f"initial assist bounds must have shape ({num_phases}, 6), got {tuple(bounds.shape)}"
        )
    return identical_axis_bounds(bounds) if mode.identical_initial_bounds else bounds


def load_run_config(run_dir: str | Path) -> TrainConfig:
    """The TrainConfig saved in a run folder."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(
            f"{path} not found: '{run_dir}' is not a run folder made by `a2cf-mb train`"
        )
    return TrainConfig.from_dict(json.loads(path.read_text())["train"])


def _env_config_dict(env: VecEnv) -> Any:
    cfg = env.cfg
    if dataclasses.is_dataclass(cfg):
        return json.loads(json.dumps(asdict(cfg), default=str))
    return json.loads(json.dumps(cfg, default=str))


def _new_run_dir(cfg: TrainConfig) -> Path:
    name = cfg.run_name or f"{cfg.task}_{cfg.mode}_{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}"
    run_dir = Path(cfg.out) / name
    if (run_dir / CONFIG_FILE).exists():
        raise FileExistsError(
            f"run folder {run_dir} already holds a run: pick another --run-name or use --resume"
        )
    return run_dir


def train(cfg: TrainConfig, eta0: torch.Tensor | None = None, verbose: bool = True) -> TrainResult:
    """Train (or resume) one run; see the module docstring for the run folder.

    Args:
        cfg: the run configuration. With ``cfg.resume`` set, the saved config of that run folder is
            used, except ``iterations`` (the new total) taken from ``cfg``.
        eta0: initial assist bounds (num_phases, 6) overriding the paper's table (the place where
            an oracle artifact's bounds come in).
        verbose: print rsl-rl's per-iteration progress block.
    """
    from rl.envs import make_env  # the env package is the other half of the RL core

    if cfg.resume:
        run_dir = Path(cfg.resume)
        saved = load_run_config(run_dir)
        cfg = dataclasses.replace(saved, iterations=cfg.iterations, resume=cfg.resume)
        checkpoint = run_dir / CHECKPOINT_DIR / LAST_CHECKPOINT
        if not checkpoint.is_file():
            raise FileNotFoundError(
                f"no checkpoint at {checkpoint}: nothing to resume in '{run_dir}'"
            )
    else:
        run_dir = _new_run_dir(cfg)
        checkpoint = None

    seed_everything(cfg.seed)
    mode = get_mode(cfg.mode)
    env = make_env(cfg.task, cfg.num_envs, seed=cfg.seed)
    env.set_random_mask_prob(cfg.random_mask_prob if mode.random_mask else 0.0)
    curriculum = AssistCurriculum(
        initial_bounds(cfg.task, env.num_phases, mode, eta0, env.task.default_assist_bound()),
        cfg.curriculum,
    )
    learner_env: VecEnv = env if mode.assist else MotionOnlyEnv(env)
    rsl_cfg = rsl_rl_config(cfg, mode)
    run_dir.mkdir(parents=True, exist_ok=True)  # only once the task and env are known to work

    quiet: Any = contextlib.nullcontext() if verbose else contextlib.redirect_stdout(io.StringIO())
    with quiet:
        runner = A2CFRunner(learner_env, rsl_cfg, run_dir, mode, curriculum, device=cfg.device)
    runner.add_git_repo_to_log(str(Path(__file__).resolve().parent))
    if checkpoint is not None:
        runner.load_checkpoint(checkpoint)
    else:
        (run_dir / CONFIG_FILE).write_text(
            json.dumps(
                {
                    "train": cfg.to_dict(),
                    "env": _env_config_dict(env),
                    "rsl_rl": rsl_cfg,
                    "eta0": curriculum.eta0.tolist(),
                },
                indent=2,
                default=str,
            )
        )
        (run_dir / "git.json").write_text(
            json.dumps(git_revision(Path(__file__).resolve().parent), indent=2)
        )

    remaining = cfg.iterations - runner.current_learning_iteration
    try:
        if remaining > 0:
            with quiet:
                runner.learn(remaining, init_at_random_ep_len=cfg.random_episode_start)
    finally:
        env.close()

    metrics = summarise(runner, cfg)
    if cfg.export_onnx:
        from rl.export import export_motion_policy

        export = export_motion_policy(runner.alg.get_policy(), run_dir / POLICY_FILE)
        metrics["onnx"] = export
    (run_dir / METRICS_FILE).write_text(json.dumps(metrics, indent=2))
    return TrainResult(
        run_dir=run_dir, iterations_done=runner.current_learning_iteration, metrics=metrics
    )


def summarise(runner: A2CFRunner, cfg: TrainConfig) -> dict[str, Any]:
    """Run summary (first/last figures, speeds, curriculum state) plus the per-iteration rows."""
    rows = runner.history
    summary: dict[str, Any] = {
        "task": cfg.task,
        "mode": cfg.mode,
        "num_envs": cfg.num_envs,
        "num_steps_per_env": cfg.num_steps_per_env,
        "iterations_done": runner.current_learning_iteration,
        "curriculum": {
            "eta": runner.curriculum.eta.tolist(),
            "assist_enabled": runner.curriculum.assist_enabled,
            "less_assist_reward": runner.curriculum.less_assist_reward,
        }
        if runner.mode.assist
        else None,
    }
    if rows:
        summary["mean_iteration_time_s"] = float(np.mean([r["iteration_time_s"] for r in rows]))
        summary["mean_collect_steps_per_s"] = float(
            np.mean([r["collect_steps_per_s"] for r in rows])
        )
        summary["mean_total_steps_per_s"] = float(np.mean([r["total_steps_per_s"] for r in rows]))
        summary["first_mean_step_reward"] = rows[0]["mean_step_reward"]
        summary["last_mean_step_reward"] = rows[-1]["mean_step_reward"]
    summary["iterations"] = rows
    return summary


@dataclass(frozen=True)
class EvalConfig:
    """Roll out a run's motion policy without assistance (``a2cf-mb eval RUN_DIR``)."""

    num_envs: int = 16  # parallel environments [-]
    num_steps: int = 0  # control steps to roll out; 0: one full episode length [-]
    seed: int = 1  # env seed (differs from training's default 0) [-]
    use_onnx: bool = True  # run the exported policy.onnx (else the last checkpoint's actor) [-]
    video: str = ""  # mp4 of env 0's first episode (needs MUJOCO_GL=egl); empty: no video [-]


def evaluate(run_dir: str | Path, cfg: EvalConfig = EvalConfig()) -> dict[str, Any]:
    """Roll out the motion policy of ``run_dir`` with assistance off; survival and return.

    Each env's *first* episode is scored: its return (sum of rewards until it ends or the rollout
    stops) and whether it survived (time-out or still running at the end, not a termination).
    The result is also written to ``RUN_DIR/eval.json``.
    """
    from rl.envs import make_env
    from rl.export import OnnxMotionPolicy

    run_dir = Path(run_dir)
    train_cfg = load_run_config(run_dir)
    env = make_env(train_cfg.task, cfg.num_envs, seed=cfg.seed)
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
    if cfg.video:
        result["video"] = str(
            _render_qpos(np.asarray(qpos_env0), env.step_dt_s, cfg.video, train_cfg.task)
        )
    (run_dir / "eval.json").write_text(json.dumps(result, indent=2))
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
