"""Tasks (skills) for the G1 env: each a :class:`rl.tasks.config.TaskConfig` of named terms
(:mod:`rl.tasks.terms`), e.g. :data:`rl.tasks.stand.STAND`; the registry is :mod:`rl.registry`.

Kept free of imports: env code imports the config types without loading any task.
"""
