"""``a2cf-mb solve-walk``: placo walk at (vx, vy, wz) -> wrench oracle artifact."""

from __future__ import annotations

import argparse

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``solve-walk`` subcommand (WalkConfig and OracleConfig fields as flags)."""
    from optimal_control.oracle import OracleConfig
    from optimal_control.walk import WalkConfig

    parser = subparsers.add_parser(
        "solve-walk",
        help="plan a G1 walk with placo and compute its assist-wrench oracle artifact",
    )
    add_config_arguments(parser, WalkConfig)
    add_config_arguments(parser, OracleConfig)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Solve and print where the artifact went."""
    from optimal_control.oracle import OracleConfig, format_summary, solve_walk
    from optimal_control.walk import WalkConfig

    art, folder = solve_walk(
        config_from_args(WalkConfig, args), config_from_args(OracleConfig, args)
    )
    print(format_summary(art, folder))
    return 0
