"""``a2cf-mb train``: train a G1 skill with A2CF (or a baseline / ablation) on rsl-rl PPO."""

from __future__ import annotations

import argparse
import dataclasses

from a2cf_mb.config_cli import add_config_arguments, config_from_args

NESTED = ("ppo", "model", "curriculum")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``train`` subcommand (one flag per TrainConfig field, nested ones prefixed)."""
    from rl.curriculum import CurriculumConfig
    from rl.runner import ModelConfig, PPOConfig, TrainConfig

    parser = subparsers.add_parser(
        "train",
        help="train a task (modes: baseline, a2cf, no-pi, no-id, no-rm); --resume RUN_DIR continues",
        description="Joint PPO (rsl-rl) over motion + assist actions with the A2CF curriculum. "
        "Writes a run folder (config, checkpoints, TensorBoard, curriculum log, metrics, ONNX).",
    )
    add_config_arguments(parser, TrainConfig, skip=NESTED)
    add_config_arguments(parser, PPOConfig, prefix="ppo_")
    add_config_arguments(parser, ModelConfig, prefix="model_")
    add_config_arguments(parser, CurriculumConfig, prefix="curriculum_")
    # On --resume the saved config is used; --iterations only overrides it when given.
    parser.set_defaults(func=run, iterations=None)


def run(args: argparse.Namespace) -> int:
    """Build the TrainConfig from the flags and call :func:`rl.runner.train`."""
    from rl.curriculum import CurriculumConfig
    from rl.runner import ModelConfig, PPOConfig, TrainConfig, load_run_config, train

    if args.resume:
        iterations = args.iterations or load_run_config(args.resume).iterations
        cfg = dataclasses.replace(TrainConfig(), resume=args.resume, iterations=iterations)
    else:
        if args.iterations is None:
            args.iterations = TrainConfig.iterations
        cfg = config_from_args(
            TrainConfig,
            args,
            ppo=config_from_args(PPOConfig, args, prefix="ppo_"),
            model=config_from_args(ModelConfig, args, prefix="model_"),
            curriculum=config_from_args(CurriculumConfig, args, prefix="curriculum_"),
        )
    result = train(cfg)
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
