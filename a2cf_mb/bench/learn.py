"""``a2cf-mb bench learn``: learning speed of A2CF against the baseline on one task.

Trains the given modes (default baseline and a2cf) one after the other with the same seed, envs,
rollout length and iteration budget, into ``OUT/<task>_<mode>``; a mode whose run folder already
holds a finished run (``metrics.json`` with the budget done) is not retrained, an unfinished one
is resumed. Then :func:`rl.compare.compare_runs` reads the run folders and writes the comparison
figure and table (``OUT/compare.png``, ``OUT/compare.json``): terrain level (or skill progress),
force bound, total and tracking reward against iterations and env steps; iterations and env steps
to given levels and to negligible force.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

from a2cf_mb.bench import register_benchmark
from rl.envs.config import EnvConfig
from rl.runner import METRICS_FILE, train
from rl.train_config import TrainConfig


@dataclass(frozen=True)
class LearnBenchConfig:
    """Budget of the learning benchmark (same for every mode)."""

    task: str = "walk"  # registered task [-]
    modes: tuple[str, ...] = ("baseline", "a2cf")  # training modes compared [-]
    num_envs: int = 64  # parallel envs per run [-]
    num_steps_per_env: int = 24  # rollout length per iteration [-]
    iterations: int = 200  # learning iterations per run [-]
    seed: int = 0  # seed of every run [-]
    num_threads: int = 0  # physics threads; 0 = all cores [-]
    levels: tuple[float, ...] = (
        1.0,
        2.0,
        3.0,
    )  # terrain levels whose first crossing is reported [-]
    eval_envs: int = (
        0  # envs of an assistance-off evaluation of each run after training; 0: none [-]
    )
    out: str = "runs/bench_learn"  # folder of the run folders and the comparison [-]
    output: str = ""  # optional json file for the figures


def _finished(run_dir: Path, iterations: int) -> bool:
    path = run_dir / METRICS_FILE
    if not path.is_file():
        return False
    return int(json.loads(path.read_text()).get("iterations_done", 0)) >= iterations


def run_learn_benchmark(cfg: LearnBenchConfig = LearnBenchConfig()) -> dict:
    """Train each mode (or reuse its finished run), then compare the runs."""
    from rl.compare import compare_runs
    from rl.evaluate import EvalConfig, evaluate

    out = Path(cfg.out)
    runs, times = [], {}
    for mode in cfg.modes:
        name = f"{cfg.task}_{mode}"
        run_dir = out / name
        if not _finished(run_dir, cfg.iterations):
            train_cfg = TrainConfig(
                task=cfg.task,
                mode=mode,
                iterations=cfg.iterations,
                num_steps_per_env=cfg.num_steps_per_env,
                out=str(out),
                run_name=name,
                resume=str(run_dir) if (run_dir / "config.json").is_file() else "",
                env=EnvConfig(num_envs=cfg.num_envs, num_threads=cfg.num_threads, seed=cfg.seed),
            )
            start = time.perf_counter()
            train(train_cfg, verbose=False)
            times[mode] = time.perf_counter() - start
            if cfg.eval_envs:
                evaluate(run_dir, EvalConfig(num_envs=cfg.eval_envs))
        runs.append(run_dir)
    result = compare_runs(runs, out, levels=cfg.levels)
    result["config"] = dataclasses.asdict(cfg)
    result["train_wall_s"] = times
    return result


def format_results(results: dict) -> str:
    """The comparison table as text."""
    from rl.compare import format_table

    return format_table(results)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench learn``."""
    register_benchmark(
        subparsers,
        "learn",
        "train baseline and a2cf with the same budget and compare their learning curves",
        LearnBenchConfig,
        run_learn_benchmark,
        format_results,
    )
