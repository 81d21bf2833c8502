"""The ``a2cf-mb`` command line. Thin: each subcommand parses a config and calls one library function.

Subcommands live in ``a2cf_mb/commands/<name>.py``; each module defines ``register(subparsers)``
which adds its parser and sets ``func`` to a callable taking the parsed namespace.
"""

from __future__ import annotations

import argparse
import importlib
import os
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


DEBUG_ENV = "A2CF_DEBUG"
"""Set this environment variable to 1 to get full tracebacks for input errors."""


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit code.

    Input errors (``ValueError``, ``FileNotFoundError`` raised with a message for the user: a bad
    flag value, a malformed clip, a missing file) print one clear line instead of a traceback.
    """
    args = build_parser().parse_args(argv)
    try:
        result = args.func(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except (ValueError, FileNotFoundError) as exc:
        if os.environ.get(DEBUG_ENV) == "1":
            raise
        print(f"a2cf-mb {args.command}: error: {exc}", file=sys.stderr)
        print(f"(set {DEBUG_ENV}=1 for the full traceback)", file=sys.stderr)
        return 2
    return int(result or 0)


if __name__ == "__main__":
    sys.exit(main())
