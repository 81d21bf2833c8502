"""``a2cf-mb bench env``: env steps per second of :class:`rl.envs.G1VecEnv` against the physics alone.

For each batch size N the same run measures, interleaved and best of ``repeats``:
- ``env``: ``G1VecEnv.step`` with random actions (motion and assist), everything included:
  wrench bound and mask, pushes, divergence checks, rewards, terminations, resets with domain
  randomisation, all observation groups;
- ``physics``: the env's physics alone: the ``Rollout`` calls the env made in a recorded stretch of
  the same run (same per-env models, thread pool, decimation, states and controls), replayed
  without anything else; the physics-only rate for this N, threads and decimation;
- ``sim``: ``bench sim``'s rollout measurement (:func:`a2cf_mb.bench.sim._rollout_rate`) on the
  env's model, one long rollout of N robots holding the stand targets (no Python round trip).
Reported as env steps/s (policy steps of all envs per second) and the ratios env / physics and
env / sim.

With ``--backends mujoco warp`` the same run also measures the env on MuJoCo Warp (the ``gpu``
extra, on ``--device``): ``env`` as above and ``physics`` as ``WarpPhysics.step`` alone with the
last controls held (:func:`measure_warp_size`), and reports warp / mujoco for each N.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from dataclasses import dataclass

import mujoco
import numpy as np
import torch
from mujoco import rollout

from a2cf_mb.bench import register_benchmark
from a2cf_mb.bench.sim import SimBenchConfig, _rollout_rate
from rl.envs.config import BACKENDS
from rl.envs.model import CONTROL_SPEC
from rl.envs.vec_env import G1VecEnv
from rl.tasks.registry import get_task, make_env
from rl.tasks.rewards import MissingContactSensorError
from robots import g1


@dataclass(frozen=True)
class EnvBenchConfig:
    """Sizes of the env benchmark."""

    num_envs: tuple[int, ...] = (64, 512)  # batch sizes to measure [-]
    num_steps: int = 100  # policy steps per measurement [-]
    warmup_steps: int = 10  # policy steps before measuring [-]
    repeats: int = 3  # measurements per case, best kept [-]
    num_threads: int = 0  # physics threads; 0 = all cores [-]
    task: str = "stand"  # registered task of the env
    action_std: float = 0.5  # std of the random actions [-]
    seed: int = 0  # random seed [-]
    link_collisions: tuple[str, ...] = (
        "on",
        "off",
    )  # link collision primitives: on, off or both [-]
    output: str = ""  # optional json file for the figures
    backends: tuple[str, ...] = ("mujoco",)  # physics backends to measure: mujoco and/or warp
    device: str = "cpu"  # Warp device of the warp backend: cpu, cuda or cuda:N


CHUNK = 5
"""Policy steps per alternating timing chunk."""


def _random_actions(env: G1VecEnv, cfg: EnvBenchConfig, generator: torch.Generator) -> torch.Tensor:
    return cfg.action_std * torch.randn(env.num_envs, env.num_actions, generator=generator)


def _record(env: G1VecEnv, cfg: EnvBenchConfig, generator: torch.Generator):
    """Run the env untimed and keep the physics inputs of every step: state and control rows."""
    states, controls = [], []
    for _ in range(cfg.num_steps):
        states.append(env.state.copy())
        env.step(_random_actions(env, cfg, generator))
        controls.append(env.control.copy())
    return states, controls


def _time_env(env: G1VecEnv, actions: list[torch.Tensor]) -> float:
    """Seconds for ``env.step`` over the given actions."""
    start = time.perf_counter()
    for a in actions:
        env.step(a)
    return time.perf_counter() - start


def _time_physics(env: G1VecEnv, runner: rollout.Rollout, datas, states, controls) -> float:
    """Seconds for replaying recorded physics calls alone (same models, threads, decimation,
    states and controls as the env used)."""
    lay, n, dec = env.layout, env.num_envs, env.cfg.decimation
    state_out = np.zeros((n, dec, lay.nstate))
    sensor_out = np.zeros((n, dec, lay.nsensordata))
    start = time.perf_counter()
    for state, control in zip(states, controls, strict=True):
        runner.rollout(
            env.models,
            datas,
            state,
            control,
            control_spec=int(CONTROL_SPEC),
            skip_checks=True,
            nstep=dec,
            initial_warmstart=None,
            state=state_out,
            sensordata=sensor_out,
            chunk_size=None,
        )
    return time.perf_counter() - start


def _warm_env(
    cfg: EnvBenchConfig, num_envs: int, link_collisions: bool, **env_overrides
) -> tuple[G1VecEnv | None, torch.Generator, dict | None]:
    """The benchmark's env after its warm-up steps (the first step compiles Warp's kernels), or
    a ``skipped`` figure when the task's terms read link contacts that the scene lacks (e.g. walk
    ends on pelvis contact, links off)."""
    task = get_task(cfg.task)
    task = dataclasses.replace(
        task, scene=dataclasses.replace(task.scene, link_collisions=link_collisions)
    )
    env = make_env(task, num_envs, seed=cfg.seed, **env_overrides)
    generator = torch.Generator().manual_seed(cfg.seed)
    try:
        env.step(_random_actions(env, cfg, generator))
    except MissingContactSensorError as err:
        env.close()
        if link_collisions:
            raise
        return (
            None,
            generator,
            {"skipped": f"task '{cfg.task}' needs the link collision primitives ({err})"},
        )
    for _ in range(cfg.warmup_steps):
        env.step(_random_actions(env, cfg, generator))
    return env, generator, None


def measure_size(num_envs: int, cfg: EnvBenchConfig, link_collisions: bool = True) -> dict:
    """Figures for one batch size.

    Env and physics are timed in alternating chunks of ``CHUNK`` steps, so the load of other
    processes on this shared machine hits both alike; each repeat gives one rate per side and the
    best repeat of each is reported.
    """
    env, generator, skipped = _warm_env(cfg, num_envs, link_collisions, num_threads=cfg.num_threads)
    if skipped:
        return skipped
    states, controls = _record(env, cfg, generator)
    datas = [mujoco.MjData(env.model) for _ in range(env.num_threads)]
    env_rate = physics = ceiling = 0.0
    ratios = []
    dec = env.cfg.decimation
    # bench sim's measurement on the env's model: one long rollout holding the stand targets.
    stand_ctrl = np.broadcast_to(g1.STAND_JOINT_POS_RAD, (num_envs, 200, g1.NUM_JOINTS)).copy()
    sim_cfg = SimBenchConfig(num_rollouts=num_envs, num_steps=200, repeats=1)
    with rollout.Rollout(nthread=env.num_threads) as runner:
        _time_physics(env, runner, datas, states[:CHUNK], controls[:CHUNK])
        for _ in range(cfg.repeats):
            env_s = physics_s = 0.0
            for c in range(0, cfg.num_steps, CHUNK):
                actions = [_random_actions(env, cfg, generator) for _ in states[c : c + CHUNK]]
                env_s += _time_env(env, actions)
                physics_s += _time_physics(
                    env, runner, datas, states[c : c + CHUNK], controls[c : c + CHUNK]
                )
            env_rate = max(env_rate, num_envs * cfg.num_steps / env_s)
            physics = max(physics, num_envs * cfg.num_steps / physics_s)
            ratios.append(physics_s / env_s)
            ceiling = max(ceiling, _rollout_rate(env.model, stand_ctrl, env.num_threads, sim_cfg))
    figures = {
        "threads": env.num_threads,
        "env_steps_per_s": env_rate,
        "physics_env_steps_per_s": physics,
        "sim_ceiling_env_steps_per_s": ceiling / dec,
        "env_over_physics": float(np.median(ratios)),
        "env_over_sim_ceiling": env_rate * dec / ceiling,
        "diverged_envs": env.diverged_total,
        "model_bytes": int(env.model.nbuffer),
        "model_copies": len({id(m) for m in env.models}),
    }
    env.close()
    return figures


def measure_warp_size(num_envs: int, cfg: EnvBenchConfig, link_collisions: bool = True) -> dict:
    """Figures for one batch size on MuJoCo Warp (``cfg.device``): ``env`` (``G1VecEnv.step``,
    everything included) and ``physics`` (``WarpPhysics.step`` alone, controls held), timed in
    alternating chunks, best of ``repeats``. The first step compiles or loads Warp's kernels and
    is not timed."""
    env, generator, skipped = _warm_env(
        cfg, num_envs, link_collisions, backend="warp", device=cfg.device
    )
    if skipped:
        return skipped
    physics = env.physics
    env_rate = physics_rate = 0.0
    for _ in range(cfg.repeats):
        env_s = physics_s = 0.0
        for _ in range(0, cfg.num_steps, CHUNK):
            env_s += _time_env(env, [_random_actions(env, cfg, generator) for _ in range(CHUNK)])
            start = time.perf_counter()
            for _ in range(CHUNK):
                physics.step()  # synchronises: the divergence check reads the state on the host
            physics_s += time.perf_counter() - start
        steps = num_envs * CHUNK * len(range(0, cfg.num_steps, CHUNK))
        env_rate = max(env_rate, steps / env_s)
        physics_rate = max(physics_rate, steps / physics_s)
    figures = {
        "device": str(physics.device),
        "env_steps_per_s": env_rate,
        "physics_env_steps_per_s": physics_rate,
        "env_over_physics": env_rate / physics_rate,
        "diverged_envs": env.diverged_total,
    }
    env.close()
    return figures


def run_env_benchmark(cfg: EnvBenchConfig = EnvBenchConfig()) -> dict:
    """Measure env and physics-only rates for each batch size (and link-collision setting and
    backend); with both backends, each size also gets the warp / mujoco ratios."""
    for value in cfg.link_collisions:
        if value not in ("on", "off"):
            raise ValueError(f"bench env --link-collisions takes on and/or off, got '{value}'")
    for value in cfg.backends:
        if value not in BACKENDS:
            raise ValueError(
                f"bench env --backends takes {' and/or '.join(BACKENDS)}, got '{value}'"
            )
    sizes: dict = {}
    for n in cfg.num_envs:
        for lc in cfg.link_collisions:
            key = f"{n} links {lc}"
            if "mujoco" in cfg.backends:
                sizes[key] = measure_size(n, cfg, link_collisions=lc == "on")
            if "warp" in cfg.backends:
                sizes[f"{key} warp"] = warp = measure_warp_size(n, cfg, link_collisions=lc == "on")
                c = sizes.get(key, {})
                if "env_steps_per_s" in c and "env_steps_per_s" in warp:
                    warp["env_over_mujoco_env"] = warp["env_steps_per_s"] / c["env_steps_per_s"]
                    warp["physics_over_mujoco_physics"] = (
                        warp["physics_env_steps_per_s"] / c["physics_env_steps_per_s"]
                    )
    results: dict = {
        "config": dataclasses.asdict(cfg),
        "mujoco": mujoco.__version__,
        "torch_threads": torch.get_num_threads(),
        "sizes": sizes,
    }
    measured = [r for r in results["sizes"].values() if "threads" in r]
    results["threads"] = measured[0]["threads"] if measured else cfg.num_threads
    return results


def format_results(results: dict) -> str:
    """A short table of the figures."""
    lines = [
        f"G1VecEnv ({results['config']['task']}), MuJoCo {results['mujoco']}, "
        f"{results['threads']} physics thread(s), policy steps of all envs per second:",
        f"  {'N, link primitives':>18} {'env':>9} {'physics':>9} {'sim':>9}  env/physics  env/sim"
        "  model MB",
    ]
    for n, r in results["sizes"].items():
        if "skipped" in r:
            lines.append(f"  {n:>18} skipped: {r['skipped']}")
            continue
        if "device" in r:  # MuJoCo Warp
            vs = ""
            if "env_over_mujoco_env" in r:
                vs = (
                    f"  warp/mujoco: env {r['env_over_mujoco_env']:.2f}, "
                    f"physics {r['physics_over_mujoco_physics']:.2f}"
                )
            lines.append(
                f"  {n:>18} {r['env_steps_per_s']:>9.0f} {r['physics_env_steps_per_s']:>9.0f} "
                f"{'-':>9}  {r['env_over_physics']:>11.2f}  ({r['device']}){vs}"
            )
            continue
        lines.append(
            f"  {n:>18} {r['env_steps_per_s']:>9.0f} {r['physics_env_steps_per_s']:>9.0f} "
            f"{r['sim_ceiling_env_steps_per_s']:>9.0f}  {r['env_over_physics']:>11.2f}  "
            f"{r['env_over_sim_ceiling']:>7.2f}  {r['model_bytes'] / 1e6:>8.2f}"
        )
    return "\n".join(lines)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench env``."""
    register_benchmark(
        subparsers,
        "env",
        "G1VecEnv steps/s vs the physics alone",
        EnvBenchConfig,
        run_env_benchmark,
        format_results,
    )
