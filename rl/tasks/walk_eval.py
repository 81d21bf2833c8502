"""Former home of the walk's evaluation, kept so that ``rl.tasks.walk_eval`` imports keep working:
it now lives in :mod:`rl.tasks.walk.evaluation`; import from there in new code."""

from rl.tasks.walk.evaluation import EVAL_JSON, EVAL_PLOT, WalkEvaluationConfig, WalkEvaluator

__all__ = ["EVAL_JSON", "EVAL_PLOT", "WalkEvaluationConfig", "WalkEvaluator"]
