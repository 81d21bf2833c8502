"""The ``a2cf-mb`` command line. Thin: each subcommand parses a config and calls one library function.

Subcommands live in ``a2cf_mb/commands/<name>.py``; each module defines ``register(subparsers)``
which adds its parser and sets ``func`` to a callable taking the parsed namespace.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMAND_MODULES: tuple[str, ...] = (
    "a2cf_mb.commands.info",
    "a2cf_mb.commands.bench",
    "a2cf_mb.commands.train",
    "a2cf_mb.commands.eval",
    "a2cf_mb.commands.solve_walk",
    "a2cf_mb.commands.solve_dance",
    "a2cf_mb.commands.solve_backflip",
)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every subcommand registered."""
    parser = argparse.ArgumentParser(
        prog="a2cf-mb",
        description="A2CF with a model-based wrench oracle for the Unitree G1.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module_name in COMMAND_MODULES:
        importlib.import_module(module_name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit code."""
    args = build_parser().parse_args(argv)
    try:
        result = args.func(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
