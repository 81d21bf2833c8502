"""Training runs: the run folder, rsl-rl's own training loop with the A2CF curriculum, checkpoints
with exact resume.

:func:`train` is the one entry point (``a2cf-mb train`` calls it). A run folder holds::

    config.json          resolved TrainConfig, the resolved task, env config and rsl-rl config
    git.json             git revision and dirty flag of the project
    git/                 rsl-rl's git diff of the code state
    events.out.tfevents* TensorBoard scalars (rsl-rl logger: Loss/*, Reward/*, Curriculum/*, ...)
    checkpoints/         last.pt (every iteration, atomic) and model_<completed iterations>.pt
    curriculum.jsonl     one line per iteration: bounds, applied wrench, switches
    metrics.json         per-iteration figures and the run summary
    policy.onnx          exported motion policy (+ policy.json describing its inputs/outputs)
    run.lock             while a process trains in it (one process at a time, rl.runs.folder)

The file names, the lock and where a run starts (new folder, resume, checkpoint rescue) are
:mod:`rl.runs.folder`'s; the warm start before PPO is :mod:`rl.a2cf.warmstart`'s.

The loop is rsl-rl's :meth:`~rsl_rl.runners.OnPolicyRunner.learn`, unforked. :class:`A2CFRunner`
wraps PPO's update with the iteration's end (:meth:`A2CFRunner.end_iteration`): the evaluation of
the policy alone when due, then Algorithm 1 (:class:`rl.a2cf.algorithm1.Algorithm1`, on every
process of a ``torchrun`` job, its statistics summed over them); rsl-rl then logs and calls
:meth:`A2CFRunner.save`, which only saves.

Under ``torchrun`` (:mod:`rl.training.distributed`) every process trains into the same run folder, which
rank 0 alone writes; each rank seeds its envs with ``seed + rank`` and learns on ``cuda:LOCAL_RANK``
(``--device cuda``) or on the CPU with the gloo backend (``--device cpu``).
"""

from __future__ import annotations

import contextlib
import io
import json
import random
import re
import sys
from collections import deque
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner
from rsl_rl.utils.logger import Logger

from optimal_control.files import (
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    git_refusal,
    git_revision,
)
from rl.a2cf.algorithm1 import (
    Algorithm1,
    RecordingEnv,
    apply_curriculum,
    curriculum_log,
    use_alone_envs,
)
from rl.a2cf.config import ModeSpec, get_mode
from rl.a2cf.curriculum import AssistCurriculum, identical_axis_bounds
from rl.a2cf.modes import MotionOnlyEnv
from rl.a2cf.warmstart import require_joint_reference, warm_start, warmstart_eta0
from rl.envs.task_schema import TaskConfig
from rl.envs.vec_env import G1VecEnv
from rl.evaluation.alone import AloneEvaluation, first_reached_once
from rl.runs.folder import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    CURRICULUM_LOG,
    GIT_FILE,
    LAST_CHECKPOINT,
    METRICS_FILE,
    METRICS_LOG,
    POLICY_FILE,
    WARMSTART_FILE,
    RunFolderLock,
    load_checkpoint,
    new_run_dir,
    recipe_changes,
    remove_unstarted_run,
    require_same_observations,
    start_point,
)
from rl.tasks.registry import resolve_task
from rl.training.config import TrainConfig, rsl_rl_config, with_task_defaults
from rl.training.distributed import (
    ProcessRank,
    check_learner_device,
    close_process_group,
    init_cpu_process_group,
    process_rank,
    rank_device,
    rank_env_config,
    rank_seed,
)
from rl.training.oracle import resolve_oracle

CHECKPOINT_FORMAT = 4
"""Version of the checkpoint layout (3: the env state part by part, ``rl.envs.vec_env.PARTS``, the
curriculum inside the env's assist part; 4: Algorithm 1's state once, under ``a2cf``; format 3
is migrated on load, :func:`migrate_checkpoint`)."""


@dataclass
class TrainResult:
    """What :func:`train` returns."""

    run_dir: Path  # the run folder
    iterations_done: int  # learning iterations completed in the run so far
    metrics: dict[str, Any]  # the content of metrics.json
    main_process: bool = True  # this process wrote the run folder (False: a torchrun rank > 0)


def _mean_of(ep_extras: list[dict], key: str) -> float | None:
    values = [float(e[key]) for e in ep_extras if key in e]
    return float(np.mean(values)) if values else None


ADAPTIVE_LR_FLOOR = 1e-5
"""The lowest learning rate of rsl-rl's adaptive (KL) schedule [-]."""

LR_FLOOR_WARN_ITERATIONS = 50
"""Consecutive iterations at (or one step above) the floor before the run warns [-]."""


def learning_rate_floored(
    rows: list[dict[str, Any]], window: int = LR_FLOOR_WARN_ITERATIONS
) -> bool:
    """Whether the last ``window`` iterations' learning rates all sat at the adaptive schedule's
    floor (or one 1.5x step above it): PPO then barely moves the policy, whatever the rewards."""
    if len(rows) < window:
        return False
    return all(r["learning_rate"] <= 1.5 * ADAPTIVE_LR_FLOOR * 1.01 for r in rows[-window:])


class RunLogger(Logger):
    """rsl-rl's logger, also keeping one metrics row per iteration for ``metrics.json``, and
    warning once when the adaptive learning rate is stuck at its floor."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.rows: list[dict[str, Any]] = []
        self.curriculum: AssistCurriculum | None = None
        self._warned_lr_floor = False

    def log(self, it: int, start_it: int, total_it: int, collect_time: float, learn_time: float,
            loss_dict: dict, learning_rate: float, *args: Any, **kwargs: Any) -> None:  # fmt: skip
        """Record the iteration's row (before rsl-rl clears its step extras), then log."""
        steps = self.cfg["num_steps_per_env"] * self.num_envs
        extras = self.ep_extras
        force = _mean_of(extras, "Curriculum/applied_force_n")
        cur = self.curriculum
        self.rows.append(
            {
                "iteration": it,
                "env_steps": steps,
                "collect_time_s": collect_time,
                "learn_time_s": learn_time,
                "iteration_time_s": collect_time + learn_time,
                "collect_steps_per_s": steps / max(collect_time, 1e-9),
                "total_steps_per_s": steps / max(collect_time + learn_time, 1e-9),
                "mean_step_reward": _mean_of(extras, "Train/mean_step_reward"),
                "mean_episode_return": float(np.mean(self.rewbuffer)) if self.rewbuffer else None,
                "mean_episode_length": float(np.mean(self.lenbuffer)) if self.lenbuffer else None,
                "skill_progress": _mean_of(extras, "Episode/skill_progress"),
                "skill_progress_alone": _mean_of(extras, "Episode/skill_progress_alone"),
                "applied_force_n": force if force is not None else 0.0,
                "eta_norm": torch.linalg.vector_norm(cur.eta, dim=-1).tolist() if cur else None,
                "assist_enabled": bool(cur and cur.assist_enabled),
                "less_assist_reward": bool(cur and cur.less_assist_reward),
                "losses": dict(loss_dict),
                "learning_rate": float(learning_rate),
            }
        )
        if not self._warned_lr_floor and learning_rate_floored(self.rows):
            self._warned_lr_floor = True
            print(
                f"a2cf-mb train: warning: the adaptive learning rate has sat at its floor "
                f"({ADAPTIVE_LR_FLOOR:g}) at the end of {LR_FLOOR_WARN_ITERATIONS} iterations: PPO's "
                "late mini-batches keep overshooting the KL target, so every update starts from "
                "the floor. Use fewer passes per rollout (--ppo-num-learning-epochs 2) or a "
                "larger batch (--num-envs)",
                file=sys.stderr,
            )
        # rsl-rl's ETA divides the time logged so far by the iterations since start_it; a resumed
        # run restores the whole run's time (state_dict), so count its iterations from 0 too
        super().log(
            it, 0, total_it, collect_time, learn_time, loss_dict, learning_rate, *args, **kwargs,
        )  # fmt: skip

    def state_dict(self) -> dict[str, Any]:
        """Totals, episode buffers and running sums (identical logs after a resume)."""
        return {
            "tot_timesteps": self.tot_timesteps,
            "tot_time": self.tot_time,
            "rewbuffer": list(self.rewbuffer),
            "lenbuffer": list(self.lenbuffer),
            "cur_reward_sum": self.cur_reward_sum.clone(),
            "cur_episode_length": self.cur_episode_length.clone(),
            "rows": list(self.rows),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.tot_timesteps = state["tot_timesteps"]
        self.tot_time = state["tot_time"]
        self.rewbuffer = deque(state["rewbuffer"], maxlen=self.rewbuffer.maxlen)
        self.lenbuffer = deque(state["lenbuffer"], maxlen=self.lenbuffer.maxlen)
        self.cur_reward_sum = state["cur_reward_sum"].clone().to(self.device)
        self.cur_episode_length = state["cur_episode_length"].clone().to(self.device)
        self.rows = list(state["rows"])


class A2CFRunner(OnPolicyRunner):
    """rsl-rl's on-policy runner, unchanged loop; adds the run folder's checkpoints and logs.

    ``current_learning_iteration`` after :meth:`load_checkpoint` is the number of *completed*
    iterations, so ``learn`` continues with the first iteration not done yet (rsl-rl's own
    ``save`` stores the last index and would repeat it).
    """

    def __init__(
        self,
        env: VecEnv,
        train_cfg: dict[str, Any],
        run_dir: Path,
        mode: ModeSpec,
        total_iterations: int,
        keep_interval: int,
        device: str = "cpu",
    ) -> None:
        """Build algorithm and logger (rsl-rl), with :class:`RunLogger` for the metrics rows."""
        super().__init__(env, train_cfg, log_dir=str(run_dir), device=device)
        self.logger = RunLogger(
            log_dir=str(run_dir),
            cfg=self.cfg,
            env_cfg=self.env.cfg,
            num_envs=self.env.num_envs,
            is_distributed=self.is_distributed,
            gpu_world_size=self.gpu_world_size,
            gpu_global_rank=self.gpu_global_rank,
            device=self.device,
        )
        self.algorithm1 = env.algorithm if isinstance(env, RecordingEnv) else None
        self.logger.curriculum = self.algorithm1.curriculum if self.algorithm1 else None
        self.run_dir = run_dir
        self.mode = mode
        self.total_iterations = total_iterations
        self.keep_interval = keep_interval
        self._saved_completed = -1
        self._done = 0  # iterations whose update is done
        self.alone_eval: AloneEvaluation | None = None  # evaluations of the policy alone
        update = self.alg.update

        def update_then_end_iteration() -> dict:
            losses = update()
            self._done += 1
            self.end_iteration(self._done)
            return losses

        self.alg.update = update_then_end_iteration  # rsl-rl's loop stays rsl-rl's

    def end_iteration(self, completed: int) -> None:
        """The end of iteration ``completed`` (1-based), after PPO's update: the evaluation of
        the policy alone when due (the main process), then Algorithm 1 and its new bounds
        applied to the env."""
        alone = self.alone_eval
        if (
            self.is_main_process
            and alone is not None
            and alone.due(completed, self.total_iterations)
        ):
            self._evaluate_alone(completed)
        if self.algorithm1 is None:
            return
        row = self.env.end_iteration()  # the RecordingEnv's: Algorithm 1, applied to the env
        # the next rollout and its update count the assist actions only while they act
        self.alg.set_helping(self.algorithm1.curriculum.assist_enabled)
        if self.logger.writer is not None:  # TensorBoard Curriculum/* with this iteration
            self.logger.ep_extras.append(curriculum_log(row, self.env.task.phase_names))

    def _configure_multi_gpu(self) -> None:
        """rsl-rl's multi-process setup (NCCL on ``cuda:LOCAL_RANK``); on the CPU the same with
        the gloo backend. A single process is rsl-rl's case: nothing is set up."""
        rank = process_rank()
        check_learner_device(self.device, rank)
        if not (rank.distributed and self.device == "cpu"):
            super()._configure_multi_gpu()
            return
        # The fields rsl-rl's version sets (the algorithm and the logger read them).
        self.gpu_world_size = rank.world_size
        self.is_distributed = True
        self.gpu_local_rank = rank.local_rank
        self.gpu_global_rank = rank.rank
        self.cfg["multi_gpu"] = {
            "global_rank": rank.rank,
            "local_rank": rank.local_rank,
            "world_size": rank.world_size,
        }
        init_cpu_process_group(rank)

    @property
    def is_main_process(self) -> bool:
        """Whether this process writes the run folder (rank 0 of a torchrun job, or the only one)."""
        return self.gpu_global_rank == 0

    @property
    def completed_iterations(self) -> int:
        """Iterations completed and checkpointed so far."""
        return max(self._saved_completed, 0)

    @property
    def history(self) -> list[dict[str, Any]]:
        """Per-iteration metrics rows so far."""
        return self.logger.rows

    def save(self, path: str, infos: dict | None = None) -> None:
        """Called by rsl-rl after every iteration: write ``checkpoints/last.pt`` atomically, keep
        ``model_<k>.pt`` every ``keep_interval`` iterations and at the end, and rewrite the
        curriculum log to match the checkpoint."""
        completed = self.current_learning_iteration + 1  # rsl-rl holds the last index here
        if completed == self._saved_completed:
            return  # rsl-rl's closing save repeats the last iteration's
        self._saved_completed = completed
        alone = self.alone_eval
        state = self.alg.save()
        state.update(
            {
                "format": CHECKPOINT_FORMAT,
                "iter": completed,
                "completed_iterations": completed,
                "env": self.env.state_dict(),
                "logger": self.logger.state_dict(),
                "torch_rng_state": torch.get_rng_state(),
                "infos": {"mode": self.mode.name, **(infos or {})},
            }
        )
        if self.algorithm1 is not None:
            state["a2cf"] = self.algorithm1.state_dict()
        if alone is not None:
            state["alone_eval"] = list(alone.rows)
        buffer = io.BytesIO()
        torch.save(state, buffer)
        data = buffer.getvalue()
        folder = self.run_dir / CHECKPOINT_DIR
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(folder / LAST_CHECKPOINT, data)
        if completed % self.keep_interval == 0 or completed == self.total_iterations:
            atomic_write_bytes(folder / f"model_{completed}.pt", data)
        self._write_curriculum_log()
        self._append_metrics_row(completed)
        if alone is not None:
            alone.write()
        self.logger.save_model(str(folder / LAST_CHECKPOINT), completed)

    def _progress_row(self, row: dict[str, Any], completed: int, total_env_steps: int) -> str:
        return json.dumps({**row, "completed": completed, "total_iterations": self.total_iterations,
                           "total_env_steps": total_env_steps}) + "\n"  # fmt: skip

    def _append_metrics_row(self, completed: int) -> None:
        """metrics.jsonl gets this iteration's row (live progress for the demo and the CLI)."""
        if not self.logger.rows:
            return
        line = self._progress_row(self.logger.rows[-1], completed, int(self.logger.tot_timesteps))
        with open(self.run_dir / METRICS_LOG, "a") as f:
            f.write(line)

    def _write_metrics_log(self) -> None:
        """metrics.jsonl = the checkpointed rows (rows of iterations after the checkpoint go)."""
        rows, size = self.logger.rows, self.cfg["num_steps_per_env"] * self.env.num_envs
        first = self.current_learning_iteration - len(rows)
        text = "".join(
            self._progress_row(row, first + k + 1, (first + k + 1) * size * self.gpu_world_size)
            for k, row in enumerate(rows)
        )
        atomic_write_text(self.run_dir / METRICS_LOG, text)

    def _env_steps_after_iteration(self) -> int:
        """Env steps of the run once this iteration is counted (rsl-rl counts at its log call,
        which comes after the iteration's end)."""
        size = self.cfg["num_steps_per_env"] * self.env.num_envs * self.gpu_world_size
        return int(self.logger.tot_timesteps) + size

    def _evaluate_alone(self, completed: int) -> None:
        """Evaluate the motion policy alone now; TensorBoard ``Eval/*`` and one printed line."""
        row = self.alone_eval(
            self.alg.get_policy().motion_policy(), completed, self._env_steps_after_iteration()
        )
        if self.algorithm1 is not None:  # the skill measure "evaluation" of Algorithm 1
            self.algorithm1.curriculum.note_evaluation(row["target_progress"])
        if self.logger.writer is not None:
            for key, value in AloneEvaluation.scalars(row).items():
                self.logger.writer.add_scalar(key, value, completed)
        metrics = row.get("task_metrics", {})
        target = self.env.task.target
        extra = (
            f", {target.metric} {metrics[target.metric]:.3f}" if target.metric in metrics else ""
        )
        print(
            f"[eval alone] iteration {completed}, {row['env_steps']:,} env steps: survival "
            f"{row['survival_fraction']:.0%}{extra} (target {row['target']}: "
            f"{'reached' if row['target_reached'] else 'not yet'})",
            file=sys.stderr,
            flush=True,
        )

    def load_checkpoint(self, path: Path) -> None:
        """Restore weights, optimisers, iteration counter, env and curriculum state, logger,
        RNG; the run then continues exactly where the checkpoint was written."""
        state = migrate_checkpoint(load_checkpoint(path, map_location=self.device))
        if state.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(
                f"{path} is a checkpoint of an older layout (format {state.get('format')}, this "
                f"version reads {CHECKPOINT_FORMAT}): it cannot be resumed exactly; start a new run"
            )
        self.alg.load(state, None, strict=True)
        self.current_learning_iteration = int(state["completed_iterations"])
        self._saved_completed = self._done = self.current_learning_iteration
        self.env.load_state_dict(state["env"])
        if self.algorithm1 is not None:
            if "a2cf" not in state:
                raise ValueError(f"{path} holds no curriculum, this run's mode needs one")
            self.algorithm1.load_state_dict(state["a2cf"])
            apply_curriculum(self.env, self.algorithm1.curriculum)
            self.alg.set_helping(self.algorithm1.curriculum.assist_enabled)
        self.logger.load_state_dict(state["logger"])
        torch.set_rng_state(state["torch_rng_state"])
        if self.alone_eval is not None:
            self.alone_eval.rows = list(state.get("alone_eval", []))
        if not self.is_main_process:
            # The checkpoint holds rank 0's envs and random state: the other ranks draw their
            # own from here on, or every rank would collect the same episodes.
            torch.manual_seed(self.env.cfg.seed)  # seed + rank (rank_env_config)
            self.env.generator.manual_seed(self.env.cfg.seed)
            return
        self._write_curriculum_log()
        self._write_metrics_log()
        if self.alone_eval is not None:
            self.alone_eval.write()

    def _write_curriculum_log(self) -> None:
        """curriculum.jsonl = the checkpointed update history (lines of iterations after the
        checkpoint, from a kill between log and save, disappear)."""
        if self.algorithm1 is None:
            return
        text = "".join(json.dumps(row) + "\n" for row in self.algorithm1.history)
        atomic_write_text(self.run_dir / CURRICULUM_LOG, text)


def seed_everything(seed: int) -> None:
    """Seed python, numpy and torch."""
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - legacy global RNG, seeded for any code that still uses it
    torch.manual_seed(seed)


def migrate_checkpoint(state: dict[str, Any]) -> dict[str, Any]:
    """A checkpoint of format 3 in format 4: the curriculum event the env's assist part held
    becomes Algorithm 1's state (saved between iterations, so no rollout is half-counted)."""
    if state.get("format") != 3:
        return state
    event = state["env"]["assist"].pop("curriculum_event", None)
    state.pop("curriculum", None)  # the second copy, never read
    if event is not None:
        if event["step_in_iteration"] != 0:
            raise ValueError("checkpoint of format 3 saved inside a rollout: start a new run")
        state["a2cf"] = {
            "curriculum": event["curriculum"],
            "iteration": event["iteration"],
            "steps": 0,
            "skill_sum": event["skill_sum"],
            "alone_sum": event.get("alone_sum", 0.0),
            "stats": event["stats"],
            "history": event["history"],
        }
    state["format"] = 4
    return state


def initial_bounds(task: TaskConfig, mode: ModeSpec, eta0: torch.Tensor | None) -> torch.Tensor:
    """Initial assist bounds (P, 6) [N, Nm]: ``eta0`` (e.g. an oracle artifact's) when given,
    else the task's default (the paper's row); the ``no-id`` mode then makes x, y, z identical."""
    bounds = task.default_assist_bound() if eta0 is None else torch.as_tensor(eta0).float()
    if bounds.shape != (task.num_phases, 6):
        raise ValueError(
            f"initial assist bounds must have shape ({task.num_phases}, 6) for task "
            f"'{task.name}', got {tuple(bounds.shape)}"
        )
    return identical_axis_bounds(bounds) if mode.identical_initial_bounds else bounds


def build_training(
    cfg: TrainConfig, run_dir: Path, eta0: torch.Tensor | None = None
) -> tuple[G1VecEnv, A2CFRunner, dict[str, Any]]:
    """The env and the runner of a run (in the assist modes the learner's env view records every
    step for Algorithm 1)."""
    mode = get_mode(cfg.mode)
    task = resolve_task(cfg)
    if cfg.resume:
        require_same_observations(run_dir, task)
        changes = recipe_changes(run_dir, task)
        if changes and process_rank().rank == 0:
            shown = "; ".join(changes[:6]) + (
                f"; and {len(changes) - 6} more" if changes[6:] else ""
            )
            print(
                f"a2cf-mb train: warning: the recipe of task '{task.name}' changed since {run_dir} "
                f"began ({shown}); the resumed iterations train on today's recipe (the run's "
                f"git.json names the commit it began on)",
                file=sys.stderr,
            )
    if eta0 is None:
        eta0 = warmstart_eta0(cfg, task)
    env = G1VecEnv(rank_env_config(cfg.env), task)
    if cfg.warmstart_motion:
        try:
            require_joint_reference(env)
        except ValueError:
            env.close()
            raise
    env.set_random_mask_prob(cfg.random_mask_prob if mode.random_mask else 0.0)
    learner_env: VecEnv = MotionOnlyEnv(env)
    if mode.assist:
        curriculum = AssistCurriculum(initial_bounds(task, mode, eta0), cfg.curriculum)
        if curriculum.num_phases != task.num_phases:
            raise ValueError(
                f"curriculum has {curriculum.num_phases} phases, task '{task.name}' has "
                f"{task.num_phases}"
            )
        learner_env = RecordingEnv(env, Algorithm1(curriculum))
    else:
        env.set_assist_enabled(False)
        env.set_less_assist_reward(False)
    if mode.coach_help:
        from rl.a2cf.coach_help import CoachHelpEnv

        learner_env = CoachHelpEnv(env, cfg.coach)
    rsl_cfg = rsl_rl_config(with_task_defaults(cfg, task), mode)
    device = rank_device(cfg.device)
    runner = A2CFRunner(
        learner_env, rsl_cfg, run_dir, mode, cfg.iterations, cfg.save_interval, device=device
    )
    if cfg.eval.interval > 0:
        runner.alone_eval = AloneEvaluation(task, cfg.env, cfg.eval, run_dir)
    return env, runner, rsl_cfg


def train(cfg: TrainConfig, eta0: torch.Tensor | None = None, verbose: bool = True) -> TrainResult:
    """Train (or resume) one run; see the module docstring for the run folder.

    Args:
        cfg: the run configuration. With ``cfg.resume`` set, the saved config of that run folder is
            used, except ``iterations`` (the new total) taken from ``cfg``.
        eta0: initial assist bounds (num_phases, 6) overriding the task's default (the place where
            an oracle artifact's bounds come in).
        verbose: print rsl-rl's per-iteration progress block.

    Under ``torchrun`` every process calls this with the same config (see :mod:`rl.training.distributed`):
    a new run then needs ``cfg.run_name``, since the default name holds the time each process
    reads, and the result of a rank other than 0 has the metrics but wrote no file.

    Raises:
        rl.runs.folder.RunFolderBusyError: another process is training in the run folder.
    """
    check_distributed(cfg, process_rank())
    run_dir = Path(cfg.resume) if cfg.resume else new_run_dir(cfg)
    # One process at a time writes a run folder: the lock comes before anything in it is read
    # (for a resume) or written.
    with RunFolderLock(run_dir, create=not cfg.resume):
        return _train_locked(cfg, run_dir, eta0, verbose)


def check_device_available(device: str, flag: str) -> None:
    """Refuse a CUDA device this machine does not have, in one line naming ``flag`` (the flag
    that chose it: ``--device``, ``--env-device``), what is there and what to give instead."""
    if not device.startswith("cuda"):
        return
    if not torch.cuda.is_available():
        why = (
            f"this torch ({torch.__version__}) is built without CUDA"
            if torch.version.cuda is None
            else "no CUDA GPU is visible (check the driver and CUDA_VISIBLE_DEVICES)"
        )
        raise ValueError(
            f"{flag} {device}: {why}; train on the CPU with {flag} cpu, or install a CUDA build "
            "of torch on a machine with a GPU (docs/gpu.md)"
        )
    index = re.fullmatch(r"cuda:(\d+)", device)
    count = torch.cuda.device_count()
    if index and int(index[1]) >= count:
        there = "cuda:0" if count == 1 else f"cuda:0 to cuda:{count - 1}"
        raise ValueError(
            f"{flag} {device}: this machine has {count} GPU{'s' * (count != 1)} ({there}); "
            f"give {flag} cuda or one that exists"
        )


def check_distributed(cfg: TrainConfig, rank: ProcessRank) -> None:
    """Refuse, under torchrun, what the processes of the job could not agree on."""
    if not rank.distributed:
        return
    if not cfg.resume and not cfg.run_name:
        raise ValueError(
            "under torchrun every process must train into the same run folder: give it a name "
            "with --run-name (the default name holds the time, which the processes read apart)"
        )
    if get_mode(cfg.mode).assist and cfg.curriculum.skill_measure == "evaluation":
        raise ValueError(
            "curriculum skill_measure 'evaluation' is not supported under torchrun (only rank 0 "
            "evaluates the policy alone, so the ranks' curricula would part): use "
            "--curriculum-skill-measure helped or alone"
        )


def _train_locked(
    cfg: TrainConfig, run_dir: Path, eta0: torch.Tensor | None, verbose: bool
) -> TrainResult:
    """:func:`train` while this process holds the run folder's lock."""
    start = start_point(cfg, run_dir)
    # A device that is not there is one line, before the env or the run folder's files.
    check_device_available(start.cfg.device, "--device")
    if start.cfg.env.backend == "warp":
        check_device_available(start.cfg.env.device, "--env-device")
    # The run folder's config holds the discount and epochs in use, so a resume keeps them;
    # and the oracle artifact it uses (--oracle: solved once per clip segment, cached).
    cfg = resolve_oracle(start.cfg)
    cfg = with_task_defaults(cfg, resolve_task(cfg))
    checkpoint = start.checkpoint
    if eta0 is None and start.saved_eta0 is not None:
        eta0 = torch.tensor(start.saved_eta0)
    seed_everything(rank_seed(cfg.seed))
    if cfg.torch_threads:
        torch.set_num_threads(cfg.torch_threads)
    quiet: Any = contextlib.nullcontext() if verbose else contextlib.redirect_stdout(io.StringIO())
    with quiet:
        env, runner, rsl_cfg = build_training(cfg, run_dir, eta0)
    # The lock made the folder (and removes it if this start fails before writing a file); the
    # other ranks of a torchrun job take no lock.
    run_dir.mkdir(parents=True, exist_ok=True)
    runner.add_git_repo_to_log(str(Path(__file__).resolve().parent))
    main = runner.is_main_process
    if checkpoint is not None:
        runner.load_checkpoint(checkpoint)
    new_folder = main and not (run_dir / CONFIG_FILE).is_file()
    if new_folder:
        _write_run_config(run_dir, cfg, env, rsl_cfg, runner.algorithm1)
    try:
        if (cfg.warmstart or cfg.warmstart_motion) and checkpoint is None:
            report = _warm_start(cfg, env, runner)
            if main:
                atomic_write_json(run_dir / WARMSTART_FILE, report)
        with quiet:
            # Random episode counters only at the start of a run: a resume continues the
            # checkpointed ones.
            _learn(runner, cfg, random_start=cfg.random_episode_start and not checkpoint)
    except Exception:
        # A new run that fails before its first checkpoint would fail the same way again (same
        # config, same seed): what it wrote goes, so no half-made folder misleads `eval`. An
        # interrupt (Ctrl-C) keeps it: `--resume` starts it over from iteration 0.
        if new_folder and not cfg.resume:
            remove_unstarted_run(run_dir)
        raise
    finally:
        env.close()
        if runner.is_distributed:
            close_process_group()
    metrics = _finish(runner, cfg, env, run_dir) if main else summarise(runner, cfg)
    return TrainResult(
        run_dir=run_dir,
        iterations_done=runner.completed_iterations,
        metrics=metrics,
        main_process=main,
    )


def _warm_start(cfg: TrainConfig, env: G1VecEnv, runner: A2CFRunner) -> dict[str, Any]:
    """The warm start before PPO (:func:`rl.a2cf.warmstart.warm_start`) on the env without its
    alone envs and unrecorded (its steps are no rollout of Algorithm 1); the curriculum's state
    is then handed to the env again."""
    learner = runner.env.env if isinstance(runner.env, RecordingEnv) else runner.env
    use_alone_envs(env, None)
    report = warm_start(cfg, env, runner.alg.actor, learner)
    if runner.algorithm1 is not None:
        use_alone_envs(env, runner.algorithm1.curriculum)
        apply_curriculum(env, runner.algorithm1.curriculum)
    return report


def _write_run_config(
    run_dir: Path,
    cfg: TrainConfig,
    env: G1VecEnv,
    rsl_cfg: dict[str, Any],
    algorithm1: Algorithm1 | None,
) -> None:
    """config.json (train config, resolved task, env and rsl-rl configs, eta0) and git.json."""
    atomic_write_json(
        run_dir / CONFIG_FILE,
        {
            "train": cfg.to_dict(),
            "task": env.task.to_json_dict(),
            "env": asdict(env.cfg),
            "rsl_rl": rsl_cfg,
            "eta0": algorithm1.curriculum.eta0.tolist() if algorithm1 is not None else None,
        },
    )
    code = Path(__file__).resolve().parent
    revision = git_revision(code)
    atomic_write_json(run_dir / GIT_FILE, revision)
    refusal = git_refusal(code) if revision["commit"] is None else None
    if refusal:  # e.g. a checkout owned by another user: the run would not name its code
        print(
            f"a2cf-mb train: warning: {run_dir / GIT_FILE} records no commit: git says "
            f"'{refusal}' (a checkout owned by another user: git config --global --add "
            f"safe.directory {code.parents[1]})",
            file=sys.stderr,
        )


def _learn(runner: A2CFRunner, cfg: TrainConfig, random_start: bool) -> None:
    """rsl-rl's loop for the iterations not done yet (``cfg.iterations`` in all)."""
    remaining = cfg.iterations - runner.completed_iterations
    if remaining > 0:
        runner.learn(remaining, init_at_random_ep_len=random_start)


def _finish(runner: A2CFRunner, cfg: TrainConfig, env: G1VecEnv, run_dir: Path) -> dict[str, Any]:
    """The ONNX export (when asked) and metrics.json; returns the metrics."""
    metrics = summarise(runner, cfg)
    if cfg.export_onnx:
        from rl.agents.export import export_motion_policy

        export = export_motion_policy(runner.alg.get_policy(), run_dir / POLICY_FILE, env=env)
        metrics["onnx"] = export
    atomic_write_json(run_dir / METRICS_FILE, metrics)
    return metrics


def summarise(runner: A2CFRunner, cfg: TrainConfig) -> dict[str, Any]:
    """Run summary (first/last figures, speeds, curriculum state) plus the per-iteration rows."""
    rows = runner.history
    cur = runner.algorithm1.curriculum if runner.algorithm1 is not None else None
    summary: dict[str, Any] = {
        "task": cfg.task,
        "mode": cfg.mode,
        "num_envs": cfg.env.num_envs,
        "num_steps_per_env": cfg.num_steps_per_env,
        "iterations_done": runner.completed_iterations,
        "curriculum": {
            "eta": cur.eta.tolist(),
            "assist_enabled": cur.assist_enabled,
            "less_assist_reward": cur.less_assist_reward,
        }
        if cur is not None
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
    alone = runner.alone_eval
    if alone is not None and alone.rows:
        held = alone.first_held()
        once = first_reached_once(alone.rows)
        summary["alone_target"] = runner.env.task.target.describe()
        # the claim: held at two consecutive evaluations (one 32-env draw reaching it flatters);
        # confirm that checkpoint on >= 128 fresh envs with `a2cf-mb eval-curve --num-envs 128`
        summary["alone_target_held_at"] = (
            {"iteration": held["iteration"], "env_steps": held["env_steps"]} if held else None
        )
        summary["alone_target_first_reached_once_at"] = (
            {"iteration": once["iteration"], "env_steps": once["env_steps"]} if once else None
        )
        summary["alone_last"] = alone.rows[-1]
        summary["alone_evaluations"] = alone.rows
    summary["iterations"] = rows
    return summary
