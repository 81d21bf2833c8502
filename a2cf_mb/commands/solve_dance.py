"""``a2cf-mb solve-dance [--clip FILE [--clip-frames A:B]]``: dance reference -> wrench oracle
artifact."""

from __future__ import annotations

import argparse

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``solve-dance`` (DanceConfig, OracleConfig and --clip-* ClipConfig flags)."""
    from optimal_control.dance import DanceConfig
    from optimal_control.motion_clip import ClipConfig
    from optimal_control.oracle import OracleConfig

    parser = subparsers.add_parser(
        "solve-dance",
        help="built-in G1 dance (or a motion clip) -> assist-wrench oracle artifact",
    )
    parser.add_argument(
        "--clip",
        default="",
        help="motion clip, .csv (xyz, quat xyzw, 29 joints) or .npz; default: built-in",
    )
    parser.add_argument(
        "--clip-frames",
        default="",
        metavar="A:B",
        help="segment: the clip's source frames A to B (B exclusive); default: all",
    )
    add_config_arguments(parser, DanceConfig)
    add_config_arguments(parser, OracleConfig)
    add_config_arguments(parser, ClipConfig, prefix="clip_")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Solve and print where the artifact went (errors are reported by :func:`a2cf_mb.cli.main`)."""
    from optimal_control.dance import DanceConfig
    from optimal_control.motion_clip import ClipConfig
    from optimal_control.oracle import OracleConfig, format_summary, solve_dance

    art, folder = solve_dance(
        config_from_args(DanceConfig, args),
        config_from_args(OracleConfig, args),
        clip=args.clip,
        clip_cfg=config_from_args(ClipConfig, args, prefix="clip_"),
        clip_frames=args.clip_frames,
    )
    print(format_summary(art, folder))
    return 0
