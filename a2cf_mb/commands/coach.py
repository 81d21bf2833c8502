"""``a2cf-mb coach ARTIFACT``: validate the oracle's coach in MuJoCo and write its figures."""

from __future__ import annotations

import argparse

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``coach`` subcommand (CoachConfig and ValidationConfig fields as flags)."""
    from optimal_control.coach import CoachConfig, ValidationConfig

    parser = subparsers.add_parser(
        "coach",
        help="replay an oracle artifact in MuJoCo with the coach (PD + feed-forward + pelvis "
        "wrench) over randomised friction, payload and pushes; write coach.json and coach.png",
    )
    parser.add_argument("artifact", help="oracle artifact folder (solve-walk/-dance/-backflip)")
    parser.add_argument(
        "--out", default="", help="output folder (default: <artifact>-coach beside the artifact)"
    )
    add_config_arguments(parser, CoachConfig)
    add_config_arguments(parser, ValidationConfig, prefix="validation_")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Validate and print the summary."""
    from optimal_control.coach import (
        CoachConfig,
        ValidationConfig,
        coach_artifact,
        format_coach_summary,
    )

    report, folder = coach_artifact(
        args.artifact,
        config_from_args(CoachConfig, args),
        config_from_args(ValidationConfig, args, prefix="validation_"),
        out=args.out,
    )
    print(format_coach_summary(report, folder))
    return 0
