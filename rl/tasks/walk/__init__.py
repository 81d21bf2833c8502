"""The ``walk`` task as a package: one module per job.

- :mod:`~rl.tasks.walk.task`: the :class:`~rl.envs.task_schema.TaskConfig` (``WALK``, ``WALK_FLAT``,
  ``WALK_PAPER``) and its observation, reward and command tables;
- :mod:`~rl.tasks.walk.terms`: the walk's reward terms and the height scan;
- :mod:`~rl.tasks.walk.command`: the velocity command (with gait clock and command curriculum);
- :mod:`~rl.tasks.walk.curriculum`: the terrain and its terrain curriculum (the skill measure);
- :mod:`~rl.tasks.walk.evaluation`: ``a2cf-mb eval``'s walk metrics and plot.
"""
