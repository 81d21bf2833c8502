"""``a2cf-mb play SKILL|BUNDLE``: a learned skill on screen, from its bundle alone."""

from __future__ import annotations

import argparse
import json

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``play`` subcommand (flags from PlayConfig)."""
    from a2cf_mb.play import PlayConfig, zoo_skills

    parser = subparsers.add_parser(
        "play",
        help="a learned skill as a video (tracking camera, reference ghost; a walk's scripted "
        "commands), from a zoo skill or a bundle folder",
    )
    parser.add_argument(
        "target",
        # a bundle folder: an exported policy's (policy.json, policy.onnx)
        help=f"a zoo skill ({', '.join(zoo_skills()) or 'none installed'}) or a bundle folder",
    )
    add_config_arguments(parser, PlayConfig)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Call :func:`a2cf_mb.play.play` (or :func:`~a2cf_mb.play.view` with ``--viewer``) and print its figures and the video's path."""
    from a2cf_mb.play import PlayConfig, play, view

    cfg = config_from_args(PlayConfig, args)
    result = (view if cfg.viewer else play)(args.target, cfg)
    print(json.dumps(result, indent=2))
    return 0
