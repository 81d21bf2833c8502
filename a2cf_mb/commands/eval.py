"""``a2cf-mb eval RUN_DIR|BUNDLE_FOLDER``: roll out a trained motion policy without assistance."""

from __future__ import annotations

import argparse
import json

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``eval`` subcommand."""
    from rl.evaluation.policy import EvalConfig

    parser = subparsers.add_parser(
        "eval",
        help="roll out a run's exported motion policy with assistance off; survival and return",
    )
    parser.add_argument(
        "run_dir",
        # an exported policy's folder (policy.json, policy.onnx) is played by the standalone
        # runner a2cf_mb/deploy/run_bundle.py
        help="run folder of `a2cf-mb train`, or an exported policy's folder",
    )
    add_config_arguments(parser, EvalConfig)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Call :func:`rl.evaluation.policy.evaluate` and print its result."""
    from a2cf_mb.deploy.evaluate import evaluate_bundle, is_bundle_folder
    from rl.evaluation.policy import EvalConfig, evaluate

    cfg = config_from_args(EvalConfig, args)
    if is_bundle_folder(args.run_dir):
        print(json.dumps(evaluate_bundle(args.run_dir, cfg), indent=2))
        return 0
    result = evaluate(args.run_dir, cfg)
    print(json.dumps(result, indent=2))
    if "sim2sim" in result:
        other = result["sim2sim"]
        print(f"{'metric':<34} {'training physics':>17} {'sim2sim':>10}")
        for key in ("survival_fraction", "mean_return", "mean_episode_length_steps"):
            print(f"{key:<34} {result[key]:>17.3f} {other[key]:>10.3f}")
        ours, theirs = result.get("task_metrics", {}), other.get("task_metrics", {})
        for key, value in ours.items():  # the task's judge, where sim2sim scored with it too
            scalar = isinstance(value, float) and isinstance(theirs.get(key), float)
            if scalar and not key.startswith("statue_"):
                print(f"{key:<34} {value:>17.3f} {theirs[key]:>10.3f}")
        other_rows = {r["command"]: r for r in theirs.get("per_command", [])}
        for row in ours.get("per_command", []):  # walk: the errors per command (or segment)
            for key in ("lin_vel_error_mps", "yaw_rate_error_rps"):
                if row["command"] in other_rows:
                    name = f"{row['command']}: {key}"
                    print(f"{name:<34} {row[key]:>17.3f} {other_rows[row['command']][key]:>10.3f}")
    return 0
