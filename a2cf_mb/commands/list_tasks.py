"""``a2cf-mb list-tasks``: the registered tasks, their phases, observation sizes and terms."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``list-tasks`` subcommand."""
    parser = subparsers.add_parser(
        "list-tasks", help="registered tasks: phases, observation group sizes, reward terms"
    )
    parser.add_argument("--json", action="store_true", help="print the table as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print one block per task (or JSON)."""
    from rl.tasks.registry import describe_tasks

    rows = describe_tasks()
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for row in rows:
        sizes = ", ".join(f"{k} {v}" for k, v in row["observation_sizes"].items())
        print(f"{row['name']}: {row['description']}")
        print(f"  phases: {', '.join(row['phases'])}; episode {row['episode_length_s']} s")
        print(f"  observations: {sizes}")
        print(f"  rewards: {', '.join(row['rewards'])}")
        print(f"  terminations: {', '.join(row['terminations'])}")
    return 0
