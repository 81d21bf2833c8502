"""``a2cf-mb train``: train a G1 skill with A2CF (or a baseline / ablation) on rsl-rl PPO."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from a2cf_mb.config_cli import add_config_arguments, config_from_args, finite_float, given_flags

TASK_PREFIX = "task."
NOT_FLAGS = ("task_overrides",)
ALWAYS_APPLIED_ON_RESUME = ("resume", "iterations")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``train`` subcommand: TrainConfig fields, nested ones prefixed (``--env-*``,
    ``--ppo-*``, ``--model-*``, ``--curriculum-*``), and the task's fields as ``--task-*``."""
    from rl.a2cf.config import MODES
    from rl.envs.task_schema import TaskConfig
    from rl.tasks.registry import get_task
    from rl.training.config import TrainConfig

    parser = subparsers.add_parser(
        "train",
        help=f"train a task (modes: {', '.join(MODES)}); --resume RUN_DIR continues",
        description="Joint PPO (rsl-rl) over motion + assist actions with the A2CF curriculum. "
        "Writes a run folder (config, checkpoints, TensorBoard, curriculum log, metrics, ONNX). "
        "--task-* flags change the chosen task's config (defaults shown are those of 'stand'; "
        "`a2cf-mb list-tasks` lists the tasks and their terms).",
        allow_abbrev=False,
    )
    add_config_arguments(parser, TrainConfig, skip=NOT_FLAGS)
    add_config_arguments(
        parser, TaskConfig, prefix=TASK_PREFIX, skip=("name", "description", "observations"),
        defaults=get_task("stand"),
    )  # fmt: skip
    parser.add_argument(
        "--task-reward-weight", nargs="+", default=[], metavar="NAME=WEIGHT",
        help="replace reward weights of the task, e.g. upright=2 termination=-100",
    )  # fmt: skip
    parser.add_argument(
        "--task-term-param",
        nargs="+",
        default=[],
        metavar="TERM.PARAM=VALUE",
        help="replace a parameter of a task term, e.g. tilted.max_tilt_rad=0.6",
    )
    parser.set_defaults(func=run)


def _number(text: str, what: str) -> float:
    try:
        return finite_float(text)
    except argparse.ArgumentTypeError as err:
        raise ValueError(f"{what}: {err}") from err


def task_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The task changes the flags ask for (stored in ``TrainConfig.task_overrides``)."""
    overrides: dict[str, Any] = dict(given_flags(args, TASK_PREFIX))
    weights: dict[str, float] = {}
    for item in args.task_reward_weight:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--task-reward-weight '{item}': write NAME=WEIGHT, e.g. upright=2")
        weights[name] = _number(value, f"--task-reward-weight {item}")
    params: dict[str, dict[str, float]] = {}
    for item in args.task_term_param:
        key, sep, value = item.partition("=")
        term, dot, param = key.partition(".")
        if not sep or not dot or not term or not param:
            raise ValueError(
                f"--task-term-param '{item}': write TERM.PARAM=VALUE, e.g. tilted.max_tilt_rad=0.6"
            )
        params.setdefault(term, {})[param] = _number(value, f"--task-term-param {item}")
    if weights:
        overrides["reward_weights"] = weights
    if params:
        overrides["term_params"] = params
    return overrides


def run(args: argparse.Namespace) -> int:
    """Build the TrainConfig from the flags and call :func:`rl.training.runner.train`."""
    from rl.runs.folder import check_resume, load_run_config, logged_iterations
    from rl.tasks.registry import get_task
    from rl.training.config import TrainConfig
    from rl.training.runner import train

    overrides = task_overrides(args)
    if args.resume:
        saved = load_run_config(args.resume)  # first: a folder that holds no run is one line
        given = given_flags(args)
        # without --iterations: the run's own total, or what it has done where a resume went
        # past it (a run's config keeps the total it began with)
        iterations = (
            args.iterations
            if "iterations" in given
            else max(saved.iterations, logged_iterations(Path(args.resume)))
        )
        ignored = [d for d in given if d not in ALWAYS_APPLIED_ON_RESUME]
        ignored += ["task-reward-weight"] * bool(args.task_reward_weight)
        ignored += ["task-term-param"] * bool(args.task_term_param)
        if ignored:
            # a resume that will be refused says only why, not what it would not apply
            check_resume(Path(args.resume), iterations, quiet=True)
            flags = " ".join("--" + d.replace(".", "-").replace("_", "-") for d in ignored)
            print(
                f"a2cf-mb train: warning: --resume continues {args.resume} with its saved config; "
                f"not applied: {flags}",
                file=sys.stderr,
            )
        cfg = TrainConfig(resume=args.resume, iterations=iterations)
    else:
        cfg = config_from_args(TrainConfig, args, task_overrides=overrides)
        get_task(cfg.task).with_overrides(overrides)  # bad names fail before any work
    result = train(cfg)
    if not result.main_process:
        return 0  # a torchrun rank > 0: rank 0 reports the run
    m = result.metrics
    print(f"run folder: {result.run_dir}")
    print(f"iterations done: {result.iterations_done}")
    if "mean_iteration_time_s" in m:
        print(
            f"mean iteration time {m['mean_iteration_time_s']:.2f} s, "
            f"{m['mean_collect_steps_per_s']:.0f} env steps/s while collecting; "
            f"mean step reward {m['first_mean_step_reward']:.3f} -> {m['last_mean_step_reward']:.3f}"
        )
    return 0
