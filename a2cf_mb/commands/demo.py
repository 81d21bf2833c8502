"""``a2cf-mb demo``: the zoo's learned skills, then one task end to end: baseline vs warm-started
A2CF, evaluation alone, report."""

from __future__ import annotations

import argparse
import sys

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` subcommand (flags from DemoConfig)."""
    from a2cf_mb.demo import DemoConfig

    parser = subparsers.add_parser(
        "demo",
        help="the learned skills, then stand (or --task dance) end to end on 2 CPU cores: "
        "baseline vs warm-started A2CF, evaluation alone, report",
        description="Play the zoo's learned skills (videos and a contact sheet), then one task end "
        "to end: train a baseline and an A2CF run whose force agent is warm-started (stand: from "
        "the posture coach; --task dance: from the oracle, solved first with a2cf-mb "
        "solve-dance), side by side (one core each; same seed, envs and budget; each evaluates "
        "its policy alone during training), evaluate both motion policies with assistance off in "
        "the training physics and in sim2sim (videos when MUJOCO_GL=egl works), and write "
        "OUT/report.md and OUT/summary.json. The terminal shows each run's iteration, env steps, "
        "episode length, assist bound and ETA; every stage logs to OUT/logs/.",
    )
    add_config_arguments(parser, DemoConfig)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Call :func:`a2cf_mb.demo.run_demo`; a failed stage is reported with its log's tail (exit
    code 1)."""
    from a2cf_mb.demo import DemoConfig, run_demo
    from a2cf_mb.progress import StageFailedError

    try:
        run_demo(config_from_args(DemoConfig, args))
    except StageFailedError as err:
        print(f"a2cf-mb demo: error: {err}", file=sys.stderr)
        return 1
    return 0
