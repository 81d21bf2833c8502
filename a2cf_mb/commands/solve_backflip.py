"""``a2cf-mb solve-backflip``: multi-phase TO of a G1 backflip -> audited oracle artifact."""

from __future__ import annotations

import argparse

from a2cf_mb.config_cli import add_config_arguments, config_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``solve-backflip`` (BackflipConfig flags, --oracle-*, --playback-*, output flags)."""
    from optimal_control.backflip.audit import AuditConfig
    from optimal_control.backflip.config import BackflipConfig
    from optimal_control.backflip.pipeline import BackflipOracleConfig, OutputConfig
    from optimal_control.backflip.playback import PlaybackConfig

    parser = subparsers.add_parser(
        "solve-backflip",
        help="whole-body backflip TO (CasADi/IPOPT) -> audit, MuJoCo check, oracle artifact",
    )
    add_config_arguments(parser, BackflipConfig)
    add_config_arguments(parser, OutputConfig)
    add_config_arguments(parser, BackflipOracleConfig, prefix="oracle_")
    # The same --overwrite as solve-walk / solve-dance (an alias; the default is the config's).
    parser.add_argument(
        "--overwrite",
        dest="oracle_overwrite",
        action=argparse.BooleanOptionalAction,
        default=argparse.SUPPRESS,
        help="same as --oracle-overwrite",
    )
    add_config_arguments(parser, PlaybackConfig, prefix="playback_")
    add_config_arguments(parser, AuditConfig, prefix="audit_")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Solve and print the summary (errors are reported by :func:`a2cf_mb.cli.main`)."""
    from optimal_control.backflip.audit import AuditConfig
    from optimal_control.backflip.config import BackflipConfig
    from optimal_control.backflip.pipeline import (
        BackflipOracleConfig,
        OutputConfig,
        format_backflip_summary,
        solve_backflip,
    )
    from optimal_control.backflip.playback import PlaybackConfig

    art, folder, report = solve_backflip(
        config_from_args(BackflipConfig, args),
        config_from_args(BackflipOracleConfig, args, prefix="oracle_"),
        config_from_args(PlaybackConfig, args, prefix="playback_"),
        config_from_args(OutputConfig, args),
        config_from_args(AuditConfig, args, prefix="audit_"),
    )
    print(format_backflip_summary(art, folder, report))
    return 0
