"""``a2cf-mb bench NAME``: rerunnable benchmarks, each reported as ratios to a reference measured
in the same run (these machines are shared and noisy).

Each benchmark lives in ``a2cf_mb/bench/<name>.py`` and defines ``register(subparsers)``.
"""

from __future__ import annotations

import argparse
import importlib

BENCHMARK_MODULES: tuple[str, ...] = (
    "a2cf_mb.bench.sim",
    "a2cf_mb.bench.env",
    "a2cf_mb.bench.qp",
    "a2cf_mb.bench.backflip",
    "a2cf_mb.bench.learn",
    "a2cf_mb.bench.train",
    "a2cf_mb.bench.terrain",
    "a2cf_mb.bench.physics",
)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench`` and one sub-subcommand per benchmark module."""
    parser = subparsers.add_parser("bench", help="run a benchmark (sim, ...)")
    bench_sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for module_name in BENCHMARK_MODULES:
        importlib.import_module(module_name).register(bench_sub)
