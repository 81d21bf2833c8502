"""Code states rules, docs keep results (issue 54): every flag's help is one line, and no
comment, docstring or help string in the packages carries a date (measured results and when they
were measured live in ``docs/``)."""

from __future__ import annotations

import argparse
import io
import re
import tokenize
from pathlib import Path

from a2cf_mb.cli import build_parser
from a2cf_mb.cli_reference import WIDTH

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rl", "a2cf_mb", "optimal_control", "robots")

HELP_COLUMN = WIDTH - 2 - argparse.HelpFormatter("x")._max_help_position
"""Characters of help (its default included) that fit one line of docs/cli.md, whatever the
flag: argparse starts the help at most 24 columns in, of WIDTH - 2."""

DATE = re.compile(
    r"\b(Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]*\.? \d{1,2}\b"
    r"|\b20[12]\d\b(?!-\d\d-\d\d)"
)
"""A day ("Dec 6", "since Dec 7") or a year (2026; an ISO timestamp in an example of a format is
not a date of a result)."""


def _options(parser: argparse.ArgumentParser, path: str = "a2cf-mb"):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _options(sub, f"{path} {name}")
        elif action.help not in (None, argparse.SUPPRESS) and action.dest != "help":
            yield path, parser, action


def test_every_flag_help_is_one_line() -> None:
    """At docs/cli.md's width each flag's help, default included, takes one line: what a field
    is goes in its help, why and what was measured in a comment or in docs/."""
    long = []
    for path, parser, action in _options(build_parser()):
        text = parser._get_formatter()._expand_help(action)
        if "\n" in text or len(text) > HELP_COLUMN:
            name = (action.option_strings or [action.dest])[0]
            long.append(f"{path} {name}: {len(text)} > {HELP_COLUMN} characters: {text}")
    assert not long, "\n".join(long)


TEXT_TOKENS = {tokenize.COMMENT, tokenize.STRING, getattr(tokenize, "FSTRING_MIDDLE", -1)}
"""Comments, string literals (docstrings, help) and the text parts of f-strings."""


def _comments_and_strings(path: Path):
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
        if tok.type in TEXT_TOKENS:
            yield tok.start[0], tok.string


def test_no_dates_in_comments_docstrings_or_help() -> None:
    """A date in code is a lab-notebook entry: the rule stays, the result and its date go to
    docs/ (a citation's year, "et al., 2023", is a reference, not an entry)."""
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if not DATE.search(path.read_text()):  # most files: no need to tokenize
                continue
            for line, text in _comments_and_strings(path):
                for match in DATE.finditer(text):
                    if "et al." in text[max(0, match.start() - 60) : match.start()]:
                        continue
                    found.append(f"{path.relative_to(ROOT)}:{line}: {match.group(0)!r}")
    assert not found, "\n".join(found)
