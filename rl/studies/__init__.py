"""Learning studies: comparisons of runs, curves to a target."""
