"""``a2cf-mb info``: print the robot summary."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``info`` subcommand."""
    parser = subparsers.add_parser("info", help="print the G1 model summary and joint table")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print :func:`robots.summary.describe_g1`."""
    from robots.summary import describe_g1

    print(describe_g1())
    return 0
