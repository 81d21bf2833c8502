"""The ``dance`` task as a package: one module per job.

- :mod:`~rl.tasks.dance.task`: the :class:`~rl.tasks.config.TaskConfig` (``DANCE_JOINTS``, ``DANCE_PAPER``,
  :func:`~rl.tasks.dance.task.dance_task`), re-exported here;
- :mod:`~rl.tasks.dance.terms`: the command layout, its step features and the tracking rewards;
- :mod:`~rl.tasks.dance.clips`: the clip library (built-in choreography cached on disk, CSV / NPZ);
- :mod:`~rl.tasks.dance.command`: the clip-tracking command;
- :mod:`~rl.tasks.dance.skill`: the skill measure (mean joint tracking error of recent episodes);
- :mod:`~rl.tasks.dance.evaluation`: ``a2cf-mb eval``'s dance metrics and plot.
"""

from rl.tasks.dance.evaluation import DanceEvaluationConfig, DanceEvaluator
from rl.tasks.dance.task import DANCE_JOINTS, DANCE_PAPER, dance_task

__all__ = ["DANCE_JOINTS", "DANCE_PAPER", "DanceEvaluationConfig", "DanceEvaluator", "dance_task"]
