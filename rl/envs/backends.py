"""The physics backend an env config names: MuJoCo C (:mod:`rl.envs.physics`) or MuJoCo Warp
(:mod:`rl.envs.warp_physics`)."""

from __future__ import annotations

import os
from typing import Any

import mujoco

from rl.envs.physics import MujocoRolloutPhysics


def make_physics(cfg: Any, model: mujoco.MjModel, models: list) -> Any:
    """The physics ``cfg.backend`` names (an :class:`rl.envs.config.EnvConfig`): MuJoCo C's
    rollout on ``cfg.num_threads`` threads, or MuJoCo Warp on ``cfg.device`` (the gpu extra,
    imported here, where it is used), for ``model`` and the per-env ``models``."""
    if cfg.backend == "warp":
        from rl.envs.warp_physics import WarpPhysics  # the gpu extra, imported where used

        return WarpPhysics(
            model, models, cfg.decimation, cfg.max_abs_qvel, cfg.device,
            nconmax_per_world=cfg.warp_nconmax_per_world,
            njmax_per_world=cfg.warp_njmax_per_world,
        )  # fmt: skip
    threads = cfg.num_threads or os.cpu_count() or 1
    return MujocoRolloutPhysics(model, models, cfg.decimation, threads, cfg.max_abs_qvel)
