"""The ``dance`` task as a package: one module per job.

- :mod:`~rl.tasks.dance.task`: the :class:`~rl.envs.task_schema.TaskConfig` (``DANCE_JOINTS``, ``DANCE_PAPER``,
  :func:`~rl.tasks.dance.task.dance_task`);
- :mod:`~rl.tasks.dance.terms`: the command layout, its step features and the tracking rewards;
- :mod:`~rl.tasks.dance.clips`: the clip library (built-in choreography cached on disk, CSV / NPZ);
- :mod:`~rl.tasks.dance.command`: the clip-tracking command;
- :mod:`~rl.tasks.dance.skill`: the skill measure (mean joint tracking error of recent episodes);
- :mod:`~rl.tasks.dance.evaluation`: ``a2cf-mb eval``'s dance metrics and plot.
"""
