"""``a2cf-mb demo``: oracle, baseline and warm-started A2CF, evaluation, report."""

from __future__ import annotations

import argparse

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` subcommand (flags from DemoConfig)."""
    from a2cf_mb.demo import DemoConfig

    parser = subparsers.add_parser(
        "demo",
        help="the method end to end on a laptop: oracle, baseline vs warm-started A2CF, eval, report",
        description="Solve the walk oracle, train a baseline and an A2CF run with a warm-started "
        "force agent (same seed, envs, budget), evaluate both with assistance off (training physics "
        "and sim2sim) and write report.md with plots and videos.",
    )
    add_config_arguments(parser, DemoConfig)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Call :func:`a2cf_mb.demo.run_demo` and print where the report is."""
    from a2cf_mb.demo import DemoConfig, run_demo

    path = run_demo(config_from_args(DemoConfig, args))
    print(f"report: {path}")
    return 0
