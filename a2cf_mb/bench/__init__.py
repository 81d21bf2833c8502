"""Benchmarks behind ``a2cf-mb bench``: each a library function returning a dict of figures."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

from a2cf_mb.config_cli import add_config_arguments, config_from_args
from optimal_control.files import atomic_write_json


def register_benchmark(
    subparsers: argparse._SubParsersAction,
    name: str,
    help_text: str,
    config_cls: type,
    run: Callable[[Any], dict],
    format_results: Callable[[dict], str],
) -> None:
    """Add ``bench NAME``: flags from ``config_cls`` (which has an ``output`` json path field),
    then run, print the formatted figures and write them as json when ``--output`` is given."""
    parser = subparsers.add_parser(name, help=help_text)
    add_config_arguments(parser, config_cls)

    def _run(args: argparse.Namespace) -> int:
        cfg = config_from_args(config_cls, args)
        results = run(cfg)
        print(format_results(results))
        if cfg.output:
            atomic_write_json(cfg.output, results)
        return 0

    parser.set_defaults(func=_run)
