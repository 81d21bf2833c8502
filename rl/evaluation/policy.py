"""Evaluation of a run's motion policy with assistance off (``a2cf-mb eval RUN_DIR``)."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import sys
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner

from optimal_control.files import atomic_write_json, atomic_write_text
from rl.a2cf.config import get_mode
from rl.a2cf.modes import MotionOnlyEnv
from rl.agents.models import ASSIST_ACTION_DIM
from rl.config_bounds import MAX_SEED, check_range
from rl.envs.config import MAX_NUM_ENVS
from rl.envs.vec_env import G1VecEnv
from rl.evaluation.alone import rollout_alone
from rl.evaluation.config import AloneEvalConfig
from rl.runs.folder import (
    CHECKPOINT_DIR,
    CHECKPOINT_EVALS_LOG,
    EVAL_FILE,
    EVALS_DIR,
    POLICY_FILE,
    REEXPORT_ADVICE,
    load_checkpoint,
    load_run_config,
    newest_readable_checkpoint,
    no_checkpoint_error,
    read_run_jsonl,
    require_same_observations,
)
from rl.tasks.registry import resolve_task
from rl.training.config import rsl_rl_config, with_task_defaults

MAX_EVAL_STEPS = 10_000_000
"""Most control steps one ``eval`` rolls out (over two days of robot time at 50 Hz) [-]."""


@dataclass(frozen=True)
class EvalConfig:
    """Roll out a run's motion policy without assistance (``a2cf-mb eval RUN_DIR``)."""

    num_envs: int = 16  # parallel environments [-]
    num_steps: int = 0  # control steps to roll out; 0: one full episode length [-]
    seed: int = 1  # env seed (differs from training's default 0) [-]
    use_onnx: bool = True  # run policy.onnx (else the last checkpoint's actor) [-]
    video: str = ""  # mp4 of env 0's first episode (needs MUJOCO_GL=egl) [-]
    # a shorter first episode (a fall) is followed by env 0's next ones up to this length, or to
    # the reference's length on a tracking task
    video_min_s: float = 6.0  # least video length: env 0's next episodes follow a fall [s]
    # tracking tasks; 0 overlays the ghost on the robot's reference pose
    video_ghost_side_m: float = 1.0  # the reference's ghost shifted to the camera's right [m]
    # below 1 every step is drawn and played slower (0.25: a flip's half second lasts 2 s)
    video_speed: float = 1.0  # video playback speed; below 1 every step is drawn [-]
    sim2sim: bool = False  # also roll the ONNX policy out in rl.evaluation.sim2sim
    # every env follows the task's scripted command sequence instead of random draws (walk: 5 s
    # each of forward, turn, sideways, stop); a video then shows the sequence
    scripted: bool = False  # follow the task's scripted commands, scored per segment

    def __post_init__(self) -> None:
        """Bound every field where it is declared; ``eval``'s flags have no prefix."""
        check_range(self.num_envs, "--num-envs", 1, MAX_NUM_ENVS)
        check_range(self.num_steps, "--num-steps", 0, MAX_EVAL_STEPS)
        check_range(self.seed, "--seed", 0, MAX_SEED)
        # the video's length is rolled out by env 0 alone: ten minutes is a long film already
        check_range(self.video_min_s, "--video-min-s", 0.0, 600.0)
        check_range(self.video_ghost_side_m, "--video-ghost-side-m", -10.0, 10.0)
        if not 0.01 <= self.video_speed <= 4.0:
            raise ValueError(
                f"eval --video-speed must be in [0.01, 4] (1: real time), got {self.video_speed}"
            )


def evaluate(run_dir: str | Path, cfg: EvalConfig = EvalConfig()) -> dict[str, Any]:
    """Roll out the motion policy of ``run_dir`` with assistance off; survival and return.

    Each env's *first* episode is scored: its return (sum of rewards until it ends or the rollout
    stops) and whether it survived (time-out or still running at the end, not a termination).
    A task with an ``evaluation`` config adds its own metrics (``task_metrics``): its evaluator's
    ``on_step(env, active, dones, extras)`` runs after every step (``active`` (N,) bool: the env is
    still in its first episode, before this step) and ``finish(run_dir) -> dict`` at the end (it
    may write plots into ``run_dir``).
    The video (``cfg.video``) replays env 0's first episode; a task whose command has a reference
    motion (:meth:`~rl.envs.components.Command.reference_qpos`) shows it as a ghost beside the
    robot. The result is also written to ``RUN_DIR/eval.json``.
    """
    from rl.agents.export import OnnxMotionPolicy

    run_dir = Path(run_dir)
    train_cfg = load_run_config(run_dir)
    # The policy's files are checked before the env is built: a damaged one is one line at once.
    checkpoint = newest_readable_checkpoint(run_dir, "a2cf-mb eval", "evaluating")
    if checkpoint is None:
        raise no_checkpoint_error(run_dir)
    require_same_observations(run_dir, resolve_task(train_cfg))
    if cfg.use_onnx:
        _require_exported_policy(run_dir, train_cfg.export_onnx)
        onnx_policy = OnnxMotionPolicy(run_dir / POLICY_FILE)

        def policy(obs: Any) -> torch.Tensor:
            return torch.from_numpy(
                onnx_policy(obs["policy"].cpu().numpy(), obs["history"].cpu().numpy())
            )

    if cfg.sim2sim:  # sim2sim runs the ONNX policy of the bundle: both checked before rollouts
        from rl.evaluation.sim2sim import load_bundle

        if not cfg.use_onnx:
            _require_exported_policy(run_dir, train_cfg.export_onnx)
            OnnxMotionPolicy(run_dir / POLICY_FILE)
        load_bundle(run_dir, resolve_task(train_cfg))
    if cfg.video:  # a video that cannot be made is one line before the rollout
        _check_video(cfg.video)
    env_cfg = dataclasses.replace(train_cfg.env, num_envs=cfg.num_envs, seed=cfg.seed)
    task = resolve_task(train_cfg)
    if cfg.scripted:
        task = dataclasses.replace(task, evaluation=_scripted_evaluation(task))
    env = G1VecEnv(env_cfg, task)
    if not cfg.use_onnx:
        torch_policy = checkpoint_motion_policy(train_cfg, env, checkpoint)

        def policy(obs: Any) -> torch.Tensor:
            return torch_policy(obs["policy"], obs["history"])

    frames = _VideoFrames()

    def record(env: G1VecEnv) -> None:
        if cfg.video:
            frames.record(env)

    with contextlib.closing(env):
        alone = rollout_alone(env, policy, cfg.num_steps, out_dir=run_dir, on_step=record)
        if cfg.video:
            segment_s = env.command_gen.reference_duration_s(0) or 0.0  # the whole reference
            min_s = max(cfg.video_min_s, segment_s)
            _extend_video(env, policy, frames, round(min_s / env.step_dt_s))
    num_steps = alone["num_steps"]
    result = {
        "run_dir": str(run_dir),
        "task": train_cfg.task,
        "mode": train_cfg.mode,
        "policy": "onnx" if cfg.use_onnx else "checkpoint",
        **({} if cfg.use_onnx else {"checkpoint": checkpoint.name}),
        **alone,
    }
    if cfg.sim2sim:
        from rl.evaluation.sim2sim import Sim2SimConfig, run_sim2sim

        result["sim2sim"] = run_sim2sim(
            run_dir, env.task, num_steps, Sim2SimConfig(num_envs=cfg.num_envs, seed=cfg.seed)
        )
    if cfg.video:
        from optimal_control.render import RenderUnavailableError

        # the figures are kept whatever the video does; written again with the video's path
        atomic_write_json(run_dir / EVAL_FILE, result)
        try:
            result["video"] = str(
                render_qpos(
                    np.asarray(frames.qpos),
                    env.step_dt_s,
                    cfg.video,
                    train_cfg.task,
                    ghost_qpos=frames.ghost_qpos(),
                    ghost_side_m=cfg.video_ghost_side_m,
                    speed=cfg.video_speed,
                    captions=frames.captions if any(frames.captions) else None,
                )
            )
        except RenderUnavailableError as err:  # no GL / no encoder: the metrics still count
            result["video_note"] = f"no video: {err}"
            warnings.warn(f"eval: {result['video_note']}", stacklevel=2)
        except Exception as err:  # a GL or encoder failure mid-video: the metrics still count
            result["video_note"] = f"no video: rendering failed ({type(err).__name__}: {err})"
            warnings.warn(f"eval: {result['video_note']}", stacklevel=2)
    atomic_write_json(run_dir / EVAL_FILE, result)
    return result


def _check_video(video: str) -> None:
    """Refuse, in one line, a ``--video`` path that cannot be written (a folder, a file as its
    folder) or a machine that cannot render (no offscreen GL, no encoder)."""
    from optimal_control.render import RenderUnavailableError, check_offscreen_rendering

    path = Path(video)
    if path.is_dir():
        raise IsADirectoryError(
            f"--video {video} is a folder: give the video's file name, e.g. {path / 'eval.mp4'}"
        )
    parent = next((p for p in path.parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        raise NotADirectoryError(
            f"--video {video}: {parent} is a file, not a folder: give a path in a folder"
        )
    try:
        check_offscreen_rendering()
    except RenderUnavailableError as err:
        raise ValueError(f"--video {video}: {err}; or evaluate without --video") from err


def _scripted_evaluation(task: Any) -> Any:
    """The task's evaluation config with its scripted command sequence (its ``scripted()``)."""
    scripted = getattr(task.evaluation, "scripted", None)
    if scripted is None:
        raise ValueError(
            f"task {task.name!r} has no scripted command sequence: --scripted is for tasks that "
            "follow commands (walk, walk-flat, walk-paper); evaluate without it"
        )
    return scripted()


def _require_exported_policy(run_dir: Path, exported: bool) -> None:
    """Refuse a run without ``policy.onnx`` with what to do (a run that is not exported, or not
    finished, still has checkpoints to evaluate)."""
    if (run_dir / POLICY_FILE).is_file():
        return
    if not exported:
        raise FileNotFoundError(
            f"{run_dir} was trained with --no-export-onnx (no {POLICY_FILE}): evaluate its last "
            f"checkpoint with `a2cf-mb eval --no-use-onnx {run_dir}`"
        )
    raise FileNotFoundError(
        f"exported policy {run_dir / POLICY_FILE} not found (the run has not finished, or the file "
        f"was removed): {REEXPORT_ADVICE.format(run_dir=run_dir)}"
    )


@contextlib.contextmanager
def one_line_errors() -> Iterator[None]:
    """For the study scripts under ``docs/results``: a missing or damaged run file, or an argument
    that is not a number, ends the script with one line naming it instead of a traceback."""
    try:
        yield
    except (FileNotFoundError, ValueError) as err:  # DamagedRunFileError is a ValueError
        sys.exit(f"{Path(sys.argv[0]).name}: {err}")


def alone_from_checkpoint(
    run_dir: str | Path,
    checkpoint: str,
    num_envs: int,
    seed: int,
    task: Any = None,
) -> tuple[G1VecEnv, torch.nn.Module]:
    """``num_envs`` fresh envs of seed ``seed`` of the run's task (or ``task``, a variant of it),
    set up as the evaluations alone set them (every part in its evaluation setting, assistance and
    the less-assist reward off, all reset), and the deterministic motion policy of the run's
    ``checkpoints/<checkpoint>`` (``policy(obs["policy"], obs["history"])``). For study scripts
    that look inside a rollout (where it falls, which link touches)."""
    run_dir = Path(run_dir)
    train_cfg = load_run_config(run_dir)
    path = run_dir / CHECKPOINT_DIR / checkpoint
    if not path.is_file():
        kept = sorted((run_dir / CHECKPOINT_DIR).glob("*.pt"), key=lambda p: p.stat().st_mtime)
        raise FileNotFoundError(
            f"{path} does not exist; the run's newest checkpoints: {[p.name for p in kept[-4:]]}"
        )
    task = resolve_task(train_cfg) if task is None else task
    env = G1VecEnv(dataclasses.replace(train_cfg.env, num_envs=num_envs, seed=seed), task)
    policy = checkpoint_motion_policy(train_cfg, env, path)
    env.for_evaluation()
    env.set_assist_enabled(False)
    env.set_less_assist_reward(False)
    env.reset_envs(torch.arange(num_envs, device=env.device))
    return env, policy


def checkpoint_motion_policy(train_cfg: Any, env: G1VecEnv, path: Path) -> torch.nn.Module:
    """The deterministic motion policy of checkpoint ``path`` of a run of ``train_cfg`` on ``env``,
    on the env's device (a damaged checkpoint: :class:`~rl.runs.folder.DamagedRunFileError` naming
    it; a checkpoint of an older recipe of the task: :class:`~rl.runs.folder.RecipeChangedError`)."""
    require_same_observations(path.parent.parent, env.task)
    state = load_checkpoint(path)
    mode = get_mode(train_cfg.mode)
    learner_env: VecEnv = env if mode.assist else MotionOnlyEnv(env)
    cfg = rsl_rl_config(with_task_defaults(train_cfg, env.task), mode)
    with contextlib.redirect_stdout(io.StringIO()):
        runner = OnPolicyRunner(learner_env, cfg, log_dir=None, device=str(env.device))
    runner.alg.load(state, {"actor": True}, strict=True)
    return runner.alg.get_policy().motion_policy().eval()


class _VideoFrames:
    """Env 0's MuJoCo qpos per recorded step (36,) and, when its task has a reference motion,
    the reference's qpos (36,) at the same step."""

    VELOCITY_MEAN_FRAMES = 25
    """Frames the caption's robot velocity is averaged over (0.5 s at 50 Hz: a gait's step)."""

    def __init__(self) -> None:
        self.qpos: list[np.ndarray] = []
        self.reference: list[np.ndarray] = []
        self.captions: list[str] = []  # per frame: the command and the robot's velocity
        self._velocity: list[tuple[float, float, float]] = []

    def __len__(self) -> int:
        return len(self.qpos)

    def record(self, env: G1VecEnv) -> None:
        """Append env 0's current state (and its reference pose, if the command has one)."""
        self.qpos.append(env.state[0, env.layout.qpos].copy())
        caption = env.command_gen.describe(0)
        if caption:  # the command beside what the robot does: its pelvis velocity (pelvis frame)
            s = env.env_state
            self._velocity.append(
                (*s.base_lin_vel_b[0, :2].tolist(), float(s.base_ang_vel_b[0, 2]))
            )
            vx, vy, wz = np.mean(self._velocity[-self.VELOCITY_MEAN_FRAMES :], axis=0)
            caption += (
                f"\nrobot (0.5 s mean): vx {vx:+.2f} m/s  vy {vy:+.2f} m/s  yaw {wz:+.2f} rad/s"
            )
        self.captions.append(caption)
        reference = env.command_gen.reference_qpos()
        if reference is not None:
            self.reference.append(np.array(reference[0], dtype=np.float64))

    def ghost_qpos(self) -> np.ndarray | None:
        """The reference's qpos (T, 36), one per frame; None for a task without a reference."""
        return np.asarray(self.reference) if self.reference else None


def _extend_video(
    env: G1VecEnv, policy: Callable[[Any], torch.Tensor], video: _VideoFrames, frames: int
) -> None:
    """Append env 0's frames, across its resets, until the video has ``frames`` frames (a policy
    that falls at once still gets a video of several seconds: fall, respawn, fall)."""
    zeros = torch.zeros(env.num_envs, ASSIST_ACTION_DIM, device=env.device)
    obs = env.get_observations()
    shape = (env.num_envs, env.num_actions - ASSIST_ACTION_DIM)
    with torch.inference_mode():
        while len(video) < frames:
            actions = policy(obs).reshape(shape).to(env.device)  # the ONNX policy's are host's
            obs, _, _, _ = env.step(torch.cat([actions, zeros], dim=-1))
            video.record(env)


def render_qpos(
    qpos: np.ndarray,
    dt_s: float,
    path: str,
    name: str,
    *,
    ghost_qpos: np.ndarray | None,
    ghost_side_m: float,
    captions: list[str] | None = None,
    speed: float = 1.0,
) -> Path:
    """Kinematic replay video of MuJoCo configurations (T, 36) with the full visual G1 model;
    ``ghost_qpos`` (T, 36): the reference pose of each frame, drawn as a ghost ``ghost_side_m``
    [m] to the camera's right; ``captions`` (T,): each frame's command in words; ``speed``:
    playback speed (below 1: every frame drawn, played slower)."""
    from optimal_control.reference import Reference
    from optimal_control.render import RenderConfig, render_reference
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
    ghost_q = None if ghost_qpos is None else mj_to_pin_q(np.asarray(ghost_qpos))
    cfg = dataclasses.replace(RenderConfig(), ghost_side_m=ghost_side_m)
    if speed != 1.0:
        stride = 1 if speed < 1.0 else cfg.frame_stride
        cfg = dataclasses.replace(cfg, frame_stride=stride, fps=speed / (dt_s * stride))
    return render_reference(ref, path, cfg, ghost_q=ghost_q, captions=captions)


def evaluate_checkpoints(
    run_dir: str | Path,
    cfg: AloneEvalConfig = AloneEvalConfig(),
    progress: bool = True,
    every_iterations: int = 1,
    iterations: tuple[int, ...] = (),
) -> list[dict[str, Any]]:
    """Evaluate the motion policy alone at every kept checkpoint ``model_<k>.pt`` of a run, as the
    evaluations during training do (same envs, seed and scores), and add the rows to
    ``evals_checkpoints.jsonl`` (checkpoints already in it with the same envs and seed are not
    evaluated again; rows of other envs or seeds stay). For runs trained without evaluations, or
    to evaluate more envs. ``every_iterations``: only checkpoints whose iteration is a multiple of
    it; ``iterations``: only these checkpoints (each must be kept). Returns the rows of these
    envs and seed."""
    run_dir = Path(run_dir)
    train_cfg = load_run_config(run_dir)
    task = resolve_task(train_cfg)
    path = run_dir / CHECKPOINT_EVALS_LOG
    advice = "delete it to evaluate every checkpoint again, or restore it from a backup"
    every = read_run_jsonl(path, "eval-curve's rows", advice) if path.is_file() else []

    def ours(row: dict[str, Any]) -> bool:
        return row.get("num_envs") == cfg.num_envs and row.get("seed") == cfg.seed

    done = {r["iteration"] for r in every if ours(r)}
    checkpoints = sorted(
        (int(p.stem.split("_")[1]), p)
        for p in (run_dir / CHECKPOINT_DIR).glob("model_*.pt")
        if p.stem.split("_")[1].isdigit()
    )
    if not checkpoints:
        raise ValueError(f"{run_dir} has no kept checkpoint (checkpoints/model_<k>.pt) to evaluate")
    missing = sorted(set(iterations) - {k for k, _ in checkpoints})
    if missing:
        raise ValueError(
            f"{run_dir} keeps no checkpoint of iteration {missing}; kept: "
            f"{[k for k, _ in checkpoints]}"
        )
    steps_per_iteration = train_cfg.env.num_envs * train_cfg.num_steps_per_env
    env_cfg = dataclasses.replace(train_cfg.env, num_envs=cfg.num_envs, seed=cfg.seed)
    todo = [
        (k, p)
        for k, p in checkpoints
        if k not in done and k % every_iterations == 0 and (not iterations or k in iterations)
    ]
    for _, ckpt in todo:  # a damaged checkpoint is one line before any rollout
        load_checkpoint(ckpt, advice="restore it from a backup, or delete it (eval-curve skips it)")
    for i, (k, ckpt) in enumerate(todo):
        env = G1VecEnv(env_cfg, task)
        try:
            policy = checkpoint_motion_policy(train_cfg, env, ckpt)
            result = rollout_alone(
                env,
                lambda obs, policy=policy: policy(obs["policy"], obs["history"]),
                out_dir=run_dir / EVALS_DIR,
            )
        finally:
            env.close()
        every.append(
            {"iteration": k, "env_steps": k * steps_per_iteration, "seed": cfg.seed, **result}
        )
        every.sort(key=lambda r: r["iteration"])  # stable: rows of one iteration keep their order
        atomic_write_text(path, "".join(json.dumps(r) + "\n" for r in every))
        if progress:
            print(
                f"[{i + 1}/{len(todo)}] {run_dir.name} iteration {k}: survival "
                f"{result['survival_fraction']:.0%}, target reached: {result['target_reached']}",
                flush=True,
            )
    return [r for r in every if ours(r)]
