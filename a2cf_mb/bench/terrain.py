"""``a2cf-mb bench terrain``: what the walk terrain costs: model size and physics rate with it.

The env's physics model (:func:`rl.envs.model.build_physics_model`, link primitives on) is built
without and with the walk task's terrain; N robots stand on tile centres (the terrain model: one
robot per tile in turn, every tile type and level; the floor model: the same states moved back
onto the floor) and are stepped by one ``Rollout`` with random joint targets held 4 physics steps.
Both are timed alternately, best of ``repeats``, in the same run; reported: ``model.nbuffer``, geom
count, physics steps/s and the ratio with / without terrain.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout

from a2cf_mb.bench import register_benchmark
from rl.envs.model import build_physics_model, model_layout
from robots import g1


@dataclass(frozen=True)
class TerrainBenchConfig:
    """Sizes of the terrain benchmark."""

    num_envs: int = 64  # robots stepped together [-]
    num_steps: int = 200  # physics steps per measurement [-]
    repeats: int = 3  # measurements per model, best kept [-]
    num_threads: int = 1  # physics threads [-]
    target_std: float = 0.3  # std of the random joint targets, in action units [-]
    seed: int = 0  # random seed [-]
    output: str = ""  # optional json file for the figures


def _states(model: mujoco.MjModel, num: int, on_terrain: bool) -> np.ndarray:
    """Stand states (num, nstate), on successive tile centres (raised by their spawn height)."""
    import torch

    from rl.tasks.walk.curriculum import WALK_TERRAIN

    lay = model_layout(model)
    rows = np.tile(lay.stand_state, (num, 1))
    if on_terrain:
        t = WALK_TERRAIN
        k = torch.arange(num) % (t.num_rows * t.num_cols)
        row, col = k // t.num_cols, k % t.num_cols
        q0 = lay.qpos.start
        rows[:, q0 : q0 + 2] = t.tile_center_xy(row, col).double().cpu().numpy()
        rows[:, q0 + 2] += t.spawn_height_m[row, col].double().cpu().numpy()
    return rows


def run_terrain_benchmark(cfg: TerrainBenchConfig = TerrainBenchConfig()) -> dict:
    """Build both models, time both rollouts, return the figures."""
    from rl.tasks.walk.curriculum import WALK_TERRAIN

    models = {
        "floor": build_physics_model(),
        "terrain": build_physics_model(terrain=WALK_TERRAIN),
    }
    rng = np.random.default_rng(cfg.seed)
    noise = rng.normal(0.0, cfg.target_std, (cfg.num_envs, cfg.num_steps // 4 + 1, g1.NUM_JOINTS))
    held = np.repeat(noise, 4, axis=1)[:, : cfg.num_steps] * g1.ACTION_SCALE_RAD
    ctrl = g1.STAND_JOINT_POS_RAD + held
    inputs = {k: _states(m, cfg.num_envs, k == "terrain") for k, m in models.items()}
    best = dict.fromkeys(models, 0.0)
    with rollout.Rollout(nthread=cfg.num_threads) as runner:
        datas = {k: [mujoco.MjData(m) for _ in range(cfg.num_threads)] for k, m in models.items()}
        for _ in range(cfg.repeats):
            for key, model in models.items():
                start = time.perf_counter()
                runner.rollout(
                    [model] * cfg.num_envs, datas[key], inputs[key], ctrl,
                    control_spec=int(mujoco.mjtState.mjSTATE_CTRL), initial_warmstart=None,
                )  # fmt: skip
                rate = cfg.num_envs * cfg.num_steps / (time.perf_counter() - start)
                best[key] = max(best[key], rate)
    return {
        "config": dataclasses.asdict(cfg),
        "mujoco": mujoco.__version__,
        "geoms": {k: int(m.ngeom) for k, m in models.items()},
        "model_bytes": {k: int(m.nbuffer) for k, m in models.items()},
        "physics_steps_per_s": best,
        "terrain_over_floor": best["terrain"] / best["floor"],
    }


def format_results(results: dict) -> str:
    """One line per model and the ratio."""
    lines = [f"physics with / without the walk terrain, MuJoCo {results['mujoco']}:"]
    for key in ("floor", "terrain"):
        lines.append(
            f"  {key:>8}: {results['geoms'][key]:>5} geoms, "
            f"{results['model_bytes'][key] / 1e6:6.2f} MB model, "
            f"{results['physics_steps_per_s'][key]:>8.0f} physics steps/s"
        )
    lines.append(f"  terrain / floor rate: {results['terrain_over_floor']:.2f}")
    return "\n".join(lines)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench terrain``."""
    register_benchmark(
        subparsers,
        "terrain",
        "walk terrain cost: model size and physics steps/s with vs without it",
        TerrainBenchConfig,
        run_terrain_benchmark,
        format_results,
    )
