"""``a2cf-mb compare RUN...``: learning curves and milestones of several runs in one figure and table."""

from __future__ import annotations

import argparse

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``compare`` subcommand."""
    from rl.studies.compare import CompareConfig

    parser = subparsers.add_parser(
        "compare",
        help="compare run folders: terrain level, force bound, rewards vs iterations and env steps",
    )
    parser.add_argument("run_dirs", nargs="+", help="run folders written by `a2cf-mb train`")
    add_config_arguments(parser, CompareConfig)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Call :func:`rl.studies.compare.compare_runs`, print the table and write its json."""
    from rl.studies.compare import CompareConfig, compare_runs, format_table

    cfg = config_from_args(CompareConfig, args)
    result = compare_runs(args.run_dirs, cfg.out, cfg.levels, cfg.negligible_force_n)
    print(format_table(result))
    return 0
