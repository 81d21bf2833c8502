"""Configuration of the batched G1 environment (:class:`rl.envs.G1VecEnv`), task-independent.

What a task decides (scene, initial state, pushes, randomisation ranges, observation noise,
episode length) lives in its :class:`rl.envs.task_schema.TaskConfig`; the physics step itself
(0.005 s) in :class:`robots.mujoco_model.MujocoModelConfig`; the assist switches (on/off, zeta,
less-assist reward) are set at run time by the runner (:meth:`G1VecEnv.set_random_mask_prob`, ...),
the paper's zeta default living once in :data:`rl.assist.DEFAULT_RANDOM_MASK_PROB`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

BACKENDS = ("mujoco", "warp")
"""Physics backends of :class:`rl.envs.G1VecEnv`: :mod:`rl.envs.physics` (MuJoCo C) and
:mod:`rl.envs.warp_physics` (MuJoCo Warp)."""


@dataclass(frozen=True)
class EnvConfig:
    """Sizes, timing, threads, seed and switches of a :class:`G1VecEnv`."""

    num_envs: int = 128  # parallel G1 instances (128 learnt faster per env step than 512 on stand and dance, docs/results/skills_learn) [-]
    decimation: int = 4  # physics steps per policy step (0.005 s x 4 = 50 Hz policy) [-]
    num_threads: int = 0  # physics threads of the rollout pool; 0 = all cores [-]
    seed: int = 0  # seed of the env's random generator (and of the run's torch/numpy) [-]
    history_length: int = 5  # policy observations kept in the "history" group (H) [-]
    clip_actions: float = 100.0  # actions are clipped to +- this before use [-]
    noise: bool = True  # add the observation terms' noise to the noisy groups
    max_abs_qvel: float = (
        200.0  # divergence guard: rows with a larger |qvel| entry are reset [m/s, rad/s]
    )
    backend: str = "mujoco"  # physics: mujoco (MuJoCo C, CPU) or warp (MuJoCo Warp, gpu extra)
    device: str = "cpu"  # device of the physics and env tensors: cpu, cuda, cuda:N (mujoco: cpu)

    def __post_init__(self) -> None:
        for name in ("num_envs", "decimation", "history_length"):
            if getattr(self, name) < 1:
                raise ValueError(f"EnvConfig.{name} must be >= 1, got {getattr(self, name)}.")
        if self.num_threads < 0:
            raise ValueError(f"EnvConfig.num_threads must be >= 0, got {self.num_threads}.")
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
