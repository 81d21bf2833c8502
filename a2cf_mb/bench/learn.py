"""``a2cf-mb bench learn``: learning speed of A2CF against the baseline on one task.

Trains the given modes (default baseline and a2cf) and seeds one after the other with the same envs,
rollout length and iteration budget, into ``OUT/<task>_<mode>_s<seed>``, each evaluating its motion
policy alone every ``eval_interval`` iterations; a run folder that already holds a finished run
(``metrics.json`` with the budget done) is not retrained, an unfinished one is resumed. The
figures: env steps and wall time to the task's assistance-free target per run, with mean and
spread over seeds (:mod:`rl.studies.learning`). Then :func:`rl.studies.compare.compare_runs` reads the run folders and writes the comparison
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
from rl.runs.folder import CONFIG_FILE, METRICS_FILE
from rl.training.config import TrainConfig
from rl.training.runner import train


@dataclass(frozen=True)
class LearnBenchConfig:
    """Budget of the learning benchmark (same for every mode and seed)."""

    task: str = "stand"  # registered task [-]
    modes: tuple[str, ...] = ("baseline", "a2cf")  # training modes compared [-]
    seeds: tuple[int, ...] = (0, 1, 2)  # seeds, one run per mode and seed [-]
    num_envs: int = 128  # parallel envs per run [-]
    num_steps_per_env: int = 24  # rollout length per iteration [-]
    iterations: int = 977  # learning iterations per run (3 M env steps at 128 x 24) [-]
    num_threads: int = 0  # physics threads; 0 = all cores [-]
    eval_interval: int = 40  # iterations between two evaluations of the policy alone [-]
    eval_envs: int = 32  # fresh envs of each evaluation of the policy alone [-]
    levels: tuple[float, ...] = (1.0, 2.0, 3.0)  # terrain levels whose first crossing counts [-]
    out: str = "runs/bench_learn"  # folder of the runs and the comparison [-]
    output: str = ""  # optional json file for the figures


def _finished(run_dir: Path, iterations: int) -> bool:
    path = run_dir / METRICS_FILE
    if not path.is_file():
        return False
    return int(json.loads(path.read_text()).get("iterations_done", 0)) >= iterations


def run_learn_benchmark(cfg: LearnBenchConfig = LearnBenchConfig()) -> dict:
    """Train each mode and seed (or reuse / resume its run), then compare: env steps and wall
    time to the task's assistance-free target per run, mean and spread over seeds
    (:func:`rl.studies.learning.summarise_study`), and the training curves (:func:`compare_runs`)."""
    from rl.evaluation.config import AloneEvalConfig
    from rl.studies.compare import compare_runs
    from rl.studies.learning import summarise_study

    out = Path(cfg.out)
    runs, times = [], {}
    for mode in cfg.modes:
        for seed in cfg.seeds:
            name = f"{cfg.task}_{mode}_s{seed}"
            run_dir = out / name
            if not _finished(run_dir, cfg.iterations):
                train_cfg = TrainConfig(
                    task=cfg.task,
                    mode=mode,
                    iterations=cfg.iterations,
                    num_steps_per_env=cfg.num_steps_per_env,
                    out=str(out),
                    run_name=name,
                    resume=str(run_dir) if (run_dir / CONFIG_FILE).is_file() else "",
                    env=EnvConfig(num_envs=cfg.num_envs, num_threads=cfg.num_threads, seed=seed),
                    eval=AloneEvalConfig(interval=cfg.eval_interval, num_envs=cfg.eval_envs),
                )
                start = time.perf_counter()
                train(train_cfg, verbose=False)
                times[name] = time.perf_counter() - start
            runs.append(run_dir)
    result = compare_runs(runs, out, levels=cfg.levels)
    result["study"] = summarise_study(runs, out)
    result["config"] = dataclasses.asdict(cfg)
    result["train_wall_s"] = times
    return result


def format_results(results: dict) -> str:
    """The comparison table as text."""
    from rl.studies.compare import format_table

    lines = [format_table(results), "", "assistance-free target (env steps to it, per seed):"]
    for group in results["study"]["groups"]:
        mean = group["env_steps_to_target_mean"]
        spread = (
            f"{mean / 1e6:.2f} M +- {group['env_steps_to_target_std'] / 1e6:.2f} M" if mean else "-"
        )
        lines.append(
            f"  {group['group']:<24} reached {group['reached']:<5} {spread:<20} "
            f"per seed {group['env_steps_to_target']}"
        )
    return "\n".join(lines)


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
