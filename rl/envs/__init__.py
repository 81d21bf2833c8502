"""Batched MuJoCo G1 environments for rsl-rl: :class:`G1VecEnv`, its :class:`EnvConfig`,
:func:`make_env`, the per-step :class:`EnvState` seen by tasks and reward terms."""

from rl.envs.config import EnvConfig
from rl.envs.factory import make_env
from rl.envs.state import EnvState
from rl.envs.vec_env import G1VecEnv

__all__ = ["EnvConfig", "EnvState", "G1VecEnv", "make_env"]
