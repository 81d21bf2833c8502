"""Tasks (skills) for the G1 env: each a :class:`rl.envs.task_schema.TaskConfig` of named terms
(:mod:`rl.envs.terms`), e.g. :data:`rl.tasks.stand.task.STAND`; the registry is :mod:`rl.tasks.registry`.

Kept free of imports: env code imports the config types without loading any task.
"""
