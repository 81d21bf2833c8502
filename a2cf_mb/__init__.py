"""a2cf-mb: humanoid motion skills with an adaptive assistive curriculum force and a wrench oracle.

This package holds the CLI, typed configs, run folders and the pipeline glue. The robot lives in
``robots``, the model-based oracle in ``optimal_control`` and the learning in ``rl``.
"""

__version__ = "0.1.0"
