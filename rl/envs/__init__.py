"""Batched MuJoCo G1 environments for rsl-rl: :class:`rl.envs.vec_env.G1VecEnv`, its
:class:`rl.envs.config.EnvConfig`, the per-step :class:`rl.envs.state.EnvState` seen by task
terms, and the schema tasks are written in (:mod:`rl.envs.task_schema`, :mod:`rl.envs.terms`,
:mod:`rl.envs.components`). Build one with :func:`rl.tasks.registry.make_env`.

The env is assembled from parts that own their state: :mod:`rl.envs.physics` (the simulator
behind an interface), :mod:`rl.envs.motion_action`, :mod:`rl.envs.assist_action`,
:mod:`rl.envs.observation_groups`, :mod:`rl.envs.pushes`, :mod:`rl.envs.randomization`,
:mod:`rl.envs.reset_events`, :mod:`rl.envs.contact_timers`, :mod:`rl.envs.task_components`.
Nothing here imports :mod:`rl.tasks`.

Kept free of imports, so term modules can import the state types without loading the env.
"""
