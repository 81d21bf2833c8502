"""The policy alone, sim2sim, reference rollouts and the task evaluators' glue."""
