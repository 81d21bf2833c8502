"""Configuration of the batched G1 environment (:class:`rl.envs.G1VecEnv`), task-independent.

What a task decides (scene, initial state, pushes, randomisation ranges, observation noise,
episode length) lives in its :class:`rl.envs.task_schema.TaskConfig`; the physics step itself
(0.005 s) in :class:`robots.mujoco_model.MujocoModelConfig`; the assist switches (on/off, zeta,
less-assist reward) are set at run time by the runner (:meth:`G1VecEnv.set_random_mask_prob`, ...),
the paper's zeta default living once in :data:`rl.envs.assist.DEFAULT_RANDOM_MASK_PROB`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from rl.config_bounds import MAX_SEED, check_range

BACKENDS = ("mujoco", "warp")
"""Physics backends of :class:`rl.envs.G1VecEnv`: :mod:`rl.envs.physics` (MuJoCo C) and
:mod:`rl.envs.warp_physics` (MuJoCo Warp)."""

NCONMAX_PER_WORLD = 48
"""Contacts allocated per world by MuJoCo Warp [-] (one pool of ``48 * N`` shared by all worlds;
mujoco_warp's own G1 benchmark size; a standing G1 has 8 sole contacts, a fallen one about 20-30).
Overflowing the pool is a :class:`rl.envs.warp_physics.ContactPoolOverflowError`."""
NJMAX_PER_WORLD = 300
"""Constraint rows per world in MuJoCo Warp, a hard limit [-] (mjlab's flat G1; pyramidal
contacts take 4 rows each, plus joint limits). Oversizing costs: buffers scale with it."""

MAX_NUM_ENVS = 2**24
"""Most envs one :class:`rl.envs.G1VecEnv` may hold (the most transitions one training iteration
may collect, :data:`rl.training.config.MAX_ROLLOUT_TRANSITIONS`) [-]."""


@dataclass(frozen=True)
class EnvConfig:
    """Sizes, timing, threads, seed and switches of a :class:`G1VecEnv`."""

    num_envs: int = 128  # parallel G1 instances [-]
    decimation: int = 4  # physics steps per policy step (4 x 0.005 s: 50 Hz) [-]
    num_threads: int = 0  # physics threads of the rollout pool; 0 = all cores [-]
    seed: int = 0  # seed of the env's generator and of the run's torch/numpy [-]
    history_length: int = 5  # policy observations kept in the "history" group (H) [-]
    clip_actions: float = 100.0  # actions are clipped to +- this before use [-]
    noise: bool = True  # add the observation terms' noise to the noisy groups
    max_abs_qvel: float = 200.0  # reset rows whose |qvel| exceeds this [m/s, rad/s]
    backend: str = "mujoco"  # physics: mujoco (MuJoCo C, CPU) or warp (gpu extra)
    device: str = "cpu"  # physics and env tensors: cpu, cuda, cuda:N (mujoco: cpu)
    warp_nconmax_per_world: int = NCONMAX_PER_WORLD  # warp: contacts per world in the pool [-]
    warp_njmax_per_world: int = NJMAX_PER_WORLD  # warp: constraint rows per world [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared; ``--env-*`` are its flags."""
        check_range(self.num_envs, "--env-num-envs", 1, MAX_NUM_ENVS)
        check_range(self.decimation, "--env-decimation", 1, 1000)
        check_range(self.num_threads, "--env-num-threads", 0, 4096)
        check_range(self.seed, "--env-seed", 0, MAX_SEED)
        check_range(self.history_length, "--env-history-length", 1, 1000)
        check_range(self.clip_actions, "--env-clip-actions", 0.0, 1e4, low_open=True)
        check_range(self.max_abs_qvel, "--env-max-abs-qvel", 0.0, 1e6, low_open=True)
        check_range(self.warp_nconmax_per_world, "--env-warp-nconmax-per-world", 1, 100_000)
        check_range(self.warp_njmax_per_world, "--env-warp-njmax-per-world", 1, 1_000_000)
        if self.backend not in BACKENDS:
            raise ValueError(
                f"EnvConfig.backend must be one of {BACKENDS}, got '{self.backend}' (--env-backend)."
            )
        if not (self.device == "cpu" or re.fullmatch(r"cuda(:\d+)?", self.device)):
            raise ValueError(
                f"EnvConfig.device must be cpu, cuda or cuda:N, got '{self.device}' (--env-device)."
            )
        if self.backend == "mujoco" and self.device != "cpu":
            raise ValueError(
                f"EnvConfig.device '{self.device}' needs --env-backend warp: MuJoCo C runs on the "
                "CPU only."
            )
