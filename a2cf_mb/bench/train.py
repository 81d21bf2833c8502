"""``a2cf-mb bench train``: where a training iteration's time goes, and end-to-end env steps/s
against the physics alone, measured in the same run.

For each configuration (batch size N, PPO epochs / mini-batches, network widths) one short real
training run (rsl-rl's own loop, a throwaway run folder) is timed by stage:

- ``env``: ``G1VecEnv.step`` (physics, terms, resets, observations), inside collection;
- ``policy``: the rest of collection (actor and critic forward passes, storage, returns);
- ``ppo``: rsl-rl's PPO update (all epochs and mini-batches);
- ``vae``: the history encoder's update;
- ``other``: checkpointing, logging, the curriculum log: the iteration's wall time minus the above.

The reference is :func:`a2cf_mb.bench.env.measure_size`'s physics-only rate for the same N and
threads (the env's own ``Rollout`` calls replayed with nothing else), measured in the same run, so
``end_to_end_over_physics`` reads on a shared, noisy machine.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from a2cf_mb.bench import register_benchmark


@dataclass(frozen=True)
class TrainBenchConfig:
    """Configurations of the training-time benchmark (every combination is measured)."""

    task: str = "stand"  # registered task [-]
    num_envs: tuple[int, ...] = (256, 512, 1024)  # batch sizes [-]
    num_steps_per_env: int = 24  # rollout length [-]
    learning_epochs: tuple[int, ...] = (5,)  # PPO passes over each rollout [-]
    mini_batches: tuple[int, ...] = (4,)  # PPO mini-batches per pass [-]
    vae_epochs: tuple[int, ...] = (0,)  # history-encoder passes over each rollout; 0 = PPO's [-]
    torch_threads: tuple[int, ...] = (1, 2)  # torch intra-op threads of the learner [-]
    iterations: int = 4  # timed iterations per configuration (after one untimed) [-]
    num_threads: int = 0  # physics threads; 0 = all cores [-]
    seed: int = 0  # seed of every run [-]
    output: str = ""  # optional json file for the figures

    def __post_init__(self) -> None:
        if self.iterations < 1 or not self.num_envs:
            raise ValueError("bench train needs iterations >= 1 and at least one num_envs")


class _Timer:
    """Accumulated seconds of a wrapped callable."""

    def __init__(self, func: Any) -> None:
        self.func = func
        self.seconds = 0.0

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        start = time.perf_counter()
        try:
            return self.func(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - start


def measure_training(
    cfg: TrainBenchConfig,
    num_envs: int,
    epochs: int,
    mini_batches: int,
    torch_threads: int,
    vae_epochs: int = 0,
) -> dict[str, Any]:
    """Stage times of ``cfg.iterations`` training iterations of one configuration."""
    from rl.envs.config import EnvConfig
    from rl.evaluation.config import AloneEvalConfig
    from rl.training.config import ModelConfig, PPOConfig, TrainConfig
    from rl.training.runner import build_training, seed_everything

    train_cfg = TrainConfig(
        task=cfg.task,
        mode="baseline",
        iterations=cfg.iterations + 1,
        num_steps_per_env=cfg.num_steps_per_env,
        env=EnvConfig(num_envs=num_envs, num_threads=cfg.num_threads, seed=cfg.seed),
        ppo=dataclasses.replace(
            PPOConfig(), num_learning_epochs=epochs, num_mini_batches=mini_batches
        ),
        model=ModelConfig(vae_learning_epochs=vae_epochs),
        eval=AloneEvalConfig(interval=0),
        export_onnx=False,
    )
    seed_everything(cfg.seed)
    torch.set_num_threads(torch_threads)
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        run_dir = Path(tmp) / "run"
        env, runner, _ = build_training(train_cfg, run_dir)
        run_dir.mkdir(parents=True)
        runner.learn(1)  # warm-up iteration (first-call allocations), untimed
        step = _Timer(env.step)
        env.step = step  # the learner env forwards to it (baseline: MotionOnlyEnv wraps env)
        update = _Timer(runner.alg.update)
        runner.alg.update = update
        encoder = _Timer(runner.alg.update_encoder)
        runner.alg.update_encoder = encoder
        start_rows = len(runner.logger.rows)
        start = time.perf_counter()
        runner.learn(cfg.iterations)
        wall = time.perf_counter() - start
        rows = runner.logger.rows[start_rows:]
        env.close()
    collect = sum(r["collect_time_s"] for r in rows)
    samples = num_envs * cfg.num_steps_per_env * cfg.iterations
    stages = {
        "env": step.seconds,
        "policy": collect - step.seconds,
        "ppo": update.seconds - encoder.seconds,
        "vae": encoder.seconds,
    }
    stages["other"] = wall - sum(stages.values())
    return {
        "num_envs": num_envs,
        "epochs": epochs,
        "mini_batches": mini_batches,
        "vae_epochs": vae_epochs or epochs,
        "torch_threads": torch_threads,
        "samples_per_iteration": num_envs * cfg.num_steps_per_env,
        "iteration_s": wall / cfg.iterations,
        "share": {k: v / wall for k, v in stages.items()},
        "end_to_end_steps_per_s": samples / wall,
        "collect_steps_per_s": samples / collect,
    }


def run_train_benchmark(cfg: TrainBenchConfig = TrainBenchConfig()) -> dict[str, Any]:
    """Every configuration's stage times, and the physics-only rate of each batch size."""
    from a2cf_mb.bench.env import EnvBenchConfig, measure_size

    results: dict[str, Any] = {"config": dataclasses.asdict(cfg), "cases": []}
    for n in cfg.num_envs:
        env_cfg = EnvBenchConfig(task=cfg.task, num_threads=cfg.num_threads, seed=cfg.seed,
                                 num_steps=50, repeats=2)  # fmt: skip
        physics = measure_size(n, env_cfg)["physics_env_steps_per_s"]
        for epochs in cfg.learning_epochs:
            for mini in cfg.mini_batches:
                for threads in cfg.torch_threads:
                    for vae in cfg.vae_epochs:
                        case = measure_training(cfg, n, epochs, mini, threads, vae)
                        case["physics_steps_per_s"] = physics
                        case["end_to_end_over_physics"] = case["end_to_end_steps_per_s"] / physics
                        results["cases"].append(case)
    return results


def format_results(results: dict[str, Any]) -> str:
    """One line per configuration: rates, the ratio to physics, and the stage shares."""
    lines = [
        f"training iteration time ({results['config']['task']}, baseline), env steps/s and shares:",
        f"  {'N':>5} {'ep':>3} {'mb':>3} {'vae':>3} {'thr':>3} {'iter s':>7} {'e2e/s':>7} "
        f"{'phys/s':>7} {'e2e/phys':>8}"
        "   env  policy  ppo   vae  other",
    ]
    for c in results["cases"]:
        s = c["share"]
        lines.append(
            f"  {c['num_envs']:>5} {c['epochs']:>3} {c['mini_batches']:>3} "
            f"{c.get('vae_epochs', c['epochs']):>3} {c['torch_threads']:>3} "
            f"{c['iteration_s']:>7.2f} "
            f"{c['end_to_end_steps_per_s']:>7.0f} {c['physics_steps_per_s']:>7.0f} "
            f"{c['end_to_end_over_physics']:>8.2f}  {s['env']:>4.0%} {s['policy']:>6.0%} "
            f"{s['ppo']:>4.0%} {s['vae']:>5.0%} {s['other']:>5.0%}"
        )
    return "\n".join(lines)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench train``."""
    register_benchmark(
        subparsers,
        "train",
        "where a training iteration's time goes; end-to-end env steps/s vs physics alone",
        TrainBenchConfig,
        run_train_benchmark,
        format_results,
    )
