"""Batched MuJoCo G1 environments for rsl-rl: :class:`rl.envs.vec_env.G1VecEnv`, its
:class:`rl.envs.config.EnvConfig`, the per-step :class:`rl.envs.state.EnvState` seen by task
terms. Build one with :func:`rl.registry.make_env`.

Kept free of imports, so term modules can import the state types without loading the env.
"""
