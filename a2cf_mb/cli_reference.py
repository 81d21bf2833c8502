"""The CLI reference (``docs/cli.md``), generated from the parser itself so it cannot drift.

``python -m a2cf_mb.cli_reference > docs/cli.md`` rewrites it; a test fails when it is stale.
"""

from __future__ import annotations

import argparse
import os
import sys

from a2cf_mb.cli import build_parser

WIDTH = 100
"""Columns of the rendered help (fixed, so the file does not depend on the terminal)."""


def _subcommands(parser: argparse.ArgumentParser, path: str = "a2cf-mb"):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _subcommands(sub, f"{path} {name}")


def render() -> str:
    """Markdown: one section per command with its ``--help`` text."""
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH)
    try:
        parts = [
            "# CLI reference",
            "",
            "Generated from the parser (`python -m a2cf_mb.cli_reference > docs/cli.md`); every "
            "flag comes from a typed config field, with its help and default.",
            "",
        ]
        for path, parser in _subcommands(build_parser()):
            parts += [f"## `{path}`", "", "```text", parser.format_help().rstrip(), "```", ""]
        return "\n".join(parts)
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous


if __name__ == "__main__":
    sys.stdout.write(render())
