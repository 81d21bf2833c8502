"""The ``track`` task as a package: motion tracking of any reference, one module per job.

- :mod:`~rl.tasks.track.task`: the :class:`~rl.envs.task_schema.TaskConfig` (``TRACK``, ``DANCE``,
  :func:`~rl.tasks.track.task.track_task`);
- :mod:`~rl.tasks.track.terms`: tracked links, command layout, reward and termination terms;
- :mod:`~rl.tasks.track.library`: the references and their links' kinematics, loaded once;
- :mod:`~rl.tasks.track.command`: the tracking command (reference state initialisation,
  adaptive start sampling, time-out at the reference's end);
- :mod:`~rl.tasks.track.skill`: the training skill measure;
- :mod:`~rl.tasks.track.evaluation`: the evaluation alone, with the statue's score beside it.
"""
