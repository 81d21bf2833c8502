"""The config of the evaluations of the policy alone during training (leaf module)."""

from __future__ import annotations

from dataclasses import dataclass

from rl.config_bounds import MAX_SEED, check_range
from rl.envs.config import MAX_NUM_ENVS


@dataclass(frozen=True)
class AloneEvalConfig:
    """Evaluations of the motion policy alone during training."""

    interval: int = 50  # iterations between evaluations (and at the end); 0: none [-]
    num_envs: int = 32  # fresh envs, one episode each [-]
    seed: int = 10_000  # seed of the evaluation envs (never a training seed) [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared; ``--eval-*`` are its flags."""
        check_range(self.interval, "--eval-interval", 0, 1_000_000_000)
        check_range(self.num_envs, "--eval-num-envs", 1, MAX_NUM_ENVS)
        check_range(self.seed, "--eval-seed", 0, MAX_SEED)
