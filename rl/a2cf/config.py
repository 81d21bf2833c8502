"""The configs of the A2CF method: the training modes, Algorithm 1's rules, the warm start and
the coach's help (leaf module: imports configs only)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from rl.config_bounds import MAX_SEED, check_range


@dataclass(frozen=True)
class ModeSpec:
    """What one training mode switches on."""

    name: str  # mode name used on the command line
    assist: bool  # train an assist head and apply its wrench
    assist_privileged: bool  # assist head reads the privileged observation (PI)
    identical_initial_bounds: bool  # same bound on x, y, z (ablation of ID)
    random_mask: bool  # drop wrench components with probability zeta (RM)
    coach_help: bool = False  # the artifact's coach helps, scaled by the failure rate


MODES: dict[str, ModeSpec] = {
    spec.name: spec
    for spec in (
        ModeSpec(
            "baseline",
            assist=False,
            assist_privileged=False,
            identical_initial_bounds=False,
            random_mask=False,
        ),
        ModeSpec(
            "a2cf",
            assist=True,
            assist_privileged=True,
            identical_initial_bounds=False,
            random_mask=True,
        ),
        ModeSpec(
            "no-pi",
            assist=True,
            assist_privileged=False,
            identical_initial_bounds=False,
            random_mask=True,
        ),
        ModeSpec(
            "no-id",
            assist=True,
            assist_privileged=True,
            identical_initial_bounds=True,
            random_mask=True,
        ),
        ModeSpec(
            "no-rm",
            assist=True,
            assist_privileged=True,
            identical_initial_bounds=False,
            random_mask=False,
        ),
        ModeSpec(
            "coach",
            assist=False,
            assist_privileged=False,
            identical_initial_bounds=False,
            random_mask=False,
            coach_help=True,
        ),
    )
}
"""All modes by name."""


def get_mode(name: str) -> ModeSpec:
    """The mode called ``name``, or a clear error listing the valid ones."""
    if name not in MODES:
        raise ValueError(f"unknown training mode '{name}': choose one of {sorted(MODES)}")
    return MODES[name]


FORCE_MEASURES: tuple[str, ...] = ("none", "mean", "quantile")


SKILL_MEASURES: tuple[str, ...] = ("evaluation", "alone", "helped")
"""Whose skill triggers the skill-learned decay (:class:`CurriculumConfig`.skill_measure)."""
"""What ``|F_k|`` of the force rule is (:class:`CurriculumConfig`.force_measure)."""


PAPER_RULES: dict[str, Any] = {
    "force_measure": "mean",
    "skill_measure": "helped",
    "skill_learned_progress": 1.0,
    "alone_share": 0.0,
    "anneal_iterations": 0,
}
"""The :class:`CurriculumConfig` fields that give the paper's Algorithm 1 exactly (the other
defaults are the paper's; the PPO side of the paper adds ``--ppo-assist-init-noise-std 1.0
--ppo-kl-actions all --ppo-assist-in-ratio always``): ``CurriculumConfig(**PAPER_RULES)``, on the command line
``--curriculum-force-measure mean --curriculum-skill-measure helped
--curriculum-skill-learned-progress 1.0 --curriculum-alone-share 0 --curriculum-anneal-iterations 0``."""


@dataclass(frozen=True)
class CurriculumConfig:
    """Hyper-parameters of the assistive-force curriculum (paper Sec. III-B, Alg. 1)."""

    epsilon: float = 0.5  # tolerance band on |F|/|eta| before the bound moves [-]
    delta: float = 0.2  # relative bound change per update [-]
    negligible_force_n: float = 0.1  # applied-wrench norm under which assistance stops [N]
    less_assist_progress: float = 0.8  # helped progress that turns on the less-assist reward [-]
    # the paper's is 1.0
    skill_learned_progress: float = 0.6  # progress of skill_measure that counts as learned [-]
    # whose skill triggers the skill-learned decay; "helped" is the paper's
    skill_measure: str = "helped"  # decay trigger: "helped", "evaluation" or "alone" [-]
    # 0 is the paper's
    alone_share: float = 0.25  # share of envs never helped (fixed env ids) [-]
    alone_window: int = 64  # finished episodes in the alone envs' skill window [-]
    # "none": the skill-learned decay only; "mean": the paper's; "quantile": force_quantile's
    force_measure: str = "none"  # |F_k| of the force rule: "none", "mean" or "quantile" [-]
    force_quantile: float = 0.9  # quantile of |F|/|eta| for force_measure "quantile" [-]
    # the help is gone after N updates; 0 is the paper's
    anneal_iterations: int = 200  # N: bound capped at eta0 (1 - k / N) at update k; 0: off [-]
    # 1 is the paper's rule
    min_phase_samples: int = 1  # least (env, step) samples of a phase for the force rule [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared (values for which Algorithm 1 is
        meaningless); ``--curriculum-*`` are its flags."""
        check_range(self.epsilon, "--curriculum-epsilon", 0.0, 1.0, high_open=True)
        check_range(self.delta, "--curriculum-delta", 0.0, 1.0, low_open=True, high_open=True)
        check_range(self.negligible_force_n, "--curriculum-negligible-force-n", 0.0, 1e5)
        # progress is a share (helped, alone) or the target's ratio (evaluation, >= 1 where
        # reached); no run reaches 100, the value for a rule that never fires
        check_range(self.less_assist_progress, "--curriculum-less-assist-progress", 0.0, 100.0)
        check_range(self.skill_learned_progress, "--curriculum-skill-learned-progress", 0.0, 100.0)
        check_range(self.alone_share, "--curriculum-alone-share", 0.0, 1.0, high_open=True)
        check_range(self.alone_window, "--curriculum-alone-window", 1, 1_000_000)
        check_range(
            self.force_quantile, "--curriculum-force-quantile", 0.0, 1.0, low_open=True,
            high_open=True,
        )  # fmt: skip
        check_range(self.anneal_iterations, "--curriculum-anneal-iterations", 0, 1_000_000_000)
        check_range(self.min_phase_samples, "--curriculum-min-phase-samples", 1, 2**24)
        if self.force_measure not in FORCE_MEASURES:
            raise ValueError(
                f"curriculum force_measure must be one of {FORCE_MEASURES}, got "
                f"'{self.force_measure}'"
            )
        if self.skill_measure not in SKILL_MEASURES:
            raise ValueError(
                f"curriculum skill_measure must be one of {SKILL_MEASURES}, got "
                f"'{self.skill_measure}'"
            )
        if self.skill_measure == "alone" and self.alone_share == 0.0:
            raise ValueError(
                "curriculum skill_measure 'alone' needs alone envs: set alone_share > 0, or "
                "skill_measure 'helped' (the paper)"
            )


@dataclass(frozen=True)
class WarmStartConfig:
    """DAgger rounds, regression and the head's initial std after the warm start."""

    # later rounds apply the student's wrench
    rounds: int = 3  # DAgger rounds (round 0 applies the coach's wrench) [-]
    steps_per_round: int = 48  # env steps collected per round [-]
    epochs: int = 30  # passes over the dataset after each round [-]
    batch_size: int = 512  # regression mini-batch [-]
    learning_rate: float = 1e-3  # Adam learning rate of the assist head [-]
    held_out: float = 0.2  # last round's share held out of the fit for the report [-]
    assist_std: float = 0.3  # std of the raw assist actions after the warm start [-]
    seed: int = 0  # shuffling seed [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared; ``--distill-*`` are its flags (upper
        bounds: what a warm start of minutes could use)."""
        check_range(self.held_out, "--distill-held-out", 0.0, 1.0, low_open=True, high_open=True)
        check_range(self.rounds, "--distill-rounds", 1, 1000)
        check_range(self.steps_per_round, "--distill-steps-per-round", 1, 10_000_000)
        check_range(self.epochs, "--distill-epochs", 1, 100_000)
        check_range(self.batch_size, "--distill-batch-size", 1, 2**24)
        check_range(self.learning_rate, "--distill-learning-rate", 0.0, 1.0, low_open=True)
        check_range(self.assist_std, "--distill-assist-std", 0.0, 100.0, low_open=True)
        check_range(self.seed, "--distill-seed", 0, MAX_SEED)


@dataclass(frozen=True)
class CoachHelpConfig:
    """The coach's help (mode ``coach``); ``--coach-*`` are its flags."""

    source: str = ""  # artifact whose coach helps in mode coach; empty: none [-]
    window: int = 256  # finished training episodes of the failure rate [-]
    failure_floor: float = 0.2  # failure rate at and below which the help is zero [-]
    max_scale: float = 0.6  # largest scale of the coach's wrench [-]
    max_force_n: float = 600.0  # the coach's wrench is clipped to this per axis [N]
    max_torque_nm: float = 200.0  # ... and its moment to this per axis [N m]

    def __post_init__(self) -> None:
        """Bound every field where it is declared."""
        check_range(self.window, "--coach-window", 1, 100_000)
        check_range(self.failure_floor, "--coach-failure-floor", 0.0, 0.99)
        check_range(self.max_scale, "--coach-max-scale", 0.0, 1.0)
        check_range(self.max_force_n, "--coach-max-force-n", 0.0, 1e4)
        check_range(self.max_torque_nm, "--coach-max-torque-nm", 0.0, 1e4)

    def scale(self, failure_rate: float) -> float:
        """beta for a failure rate in [0, 1] (the module docstring's rule)."""
        beta = 1.0 - (1.0 - failure_rate) / (1.0 - self.failure_floor)
        return min(max(beta, 0.0), self.max_scale)
