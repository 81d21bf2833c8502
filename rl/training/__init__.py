"""Training runs: TrainConfig and the rsl-rl config, the runner, train(), torchrun."""
