"""``a2cf-mb bench sim``: raw MuJoCo G1 physics throughput, the ceiling for every env benchmark.

Measures physics steps per second of the G1 (free joint, sole spheres, position actuators, dt 0.005)
single-threaded with ``mj_step`` and with all cores through ``mujoco.rollout.Rollout``, in two
regimes: holding the standing targets, and under random PD targets (more contacts change, more
solver work). Reported as steps/s and as ratios to the single-thread standing rate of the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout

from a2cf_mb.bench import register_benchmark
from robots import g1
from robots.mujoco_model import build_mujoco_model, stand_data


@dataclass(frozen=True)
class SimBenchConfig:
    """Sizes of the physics benchmark."""

    num_rollouts: int = 64  # independent G1 instances in the threaded rollout [-]
    num_steps: int = 200  # physics steps per instance and measurement [-]
    num_threads: int = 0  # threads for the rollout; 0 = all cores [-]
    repeats: int = 3  # measurements per case, best kept [-]
    random_target_std: float = 0.5  # std of random targets, in units of the action scale [-]
    seed: int = 0  # random seed [-]
    output: str = ""  # optional json file for the figures


def _single_thread_rate(model, ctrl: np.ndarray, cfg: SimBenchConfig) -> float:
    data = stand_data(model)
    steps = ctrl.shape[0]
    best = 0.0
    for _ in range(cfg.repeats):
        mujoco.mj_resetDataKeyframe(model, data, 0)
        start = time.perf_counter()
        for t in range(steps):
            data.ctrl[:] = ctrl[t]
            mujoco.mj_step(model, data)
        best = max(best, steps / (time.perf_counter() - start))
    return best


def _rollout_rate(model, ctrl: np.ndarray, nthread: int, cfg: SimBenchConfig) -> float:
    data = stand_data(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state0, spec)
    initial = np.tile(state0, (cfg.num_rollouts, 1))
    datas = [mujoco.MjData(model) for _ in range(nthread)]
    best = 0.0
    with rollout.Rollout(nthread=nthread) as runner:
        for _ in range(cfg.repeats):
            start = time.perf_counter()
            runner.rollout([model] * cfg.num_rollouts, datas, initial, ctrl)
            elapsed = time.perf_counter() - start
            best = max(best, cfg.num_rollouts * ctrl.shape[1] / elapsed)
    return best


def run_sim_benchmark(cfg: SimBenchConfig = SimBenchConfig()) -> dict:
    """Run the benchmark and return its figures (steps/s and ratios)."""
    model = build_mujoco_model()
    rng = np.random.default_rng(cfg.seed)
    nthread = cfg.num_threads or os.cpu_count() or 1
    stand = np.broadcast_to(g1.STAND_JOINT_POS_RAD, (cfg.num_steps, g1.NUM_JOINTS))
    # Random targets held for 4 physics steps (one 50 Hz control step), as a policy would.
    noise = rng.normal(
        0.0, cfg.random_target_std, (cfg.num_rollouts, cfg.num_steps // 4 + 1, g1.NUM_JOINTS)
    )
    held = np.repeat(noise, 4, axis=1)[:, : cfg.num_steps] * g1.ACTION_SCALE_RAD
    batch_random = g1.STAND_JOINT_POS_RAD + held
    random = batch_random[0]
    results = {
        "config": dataclasses.asdict(cfg),
        "threads": nthread,
        "mujoco": mujoco.__version__,
        "single_stand_steps_per_s": _single_thread_rate(model, np.array(stand), cfg),
        "single_random_steps_per_s": _single_thread_rate(model, random, cfg),
        "rollout_stand_steps_per_s": _rollout_rate(
            model, np.broadcast_to(stand, (cfg.num_rollouts, *stand.shape)).copy(), nthread, cfg
        ),
        "rollout_random_steps_per_s": _rollout_rate(model, batch_random, nthread, cfg),
    }
    reference = results["single_stand_steps_per_s"]
    results["ratios_to_single_stand"] = {
        key.removesuffix("_steps_per_s"): value / reference
        for key, value in results.items()
        if key.endswith("_steps_per_s")
    }
    results["env_steps_per_s_limit_50hz"] = results["rollout_random_steps_per_s"] / 4
    return results


def format_results(results: dict) -> str:
    """A short table of the figures."""
    lines = [f"MuJoCo {results['mujoco']} G1 physics, {results['threads']} thread(s):"]
    for key, ratio in results["ratios_to_single_stand"].items():
        rate = results[key + "_steps_per_s"]
        lines.append(f"  {key:<16} {rate:>10.0f} steps/s   x{ratio:.2f} of single_stand")
    lines.append(
        f"  => 50 Hz env-step ceiling ~{results['env_steps_per_s_limit_50hz']:.0f} steps/s"
    )
    return "\n".join(lines)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench sim``."""
    register_benchmark(
        subparsers,
        "sim",
        "raw MuJoCo G1 physics steps/s",
        SimBenchConfig,
        run_sim_benchmark,
        format_results,
    )
