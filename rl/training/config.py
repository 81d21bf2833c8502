"""Typed configs of a training run (``a2cf-mb train``) and their JSON round trip."""

from __future__ import annotations

import dataclasses
import re
import typing
from dataclasses import asdict, dataclass, field, replace
from pathlib import PurePath
from typing import TYPE_CHECKING, Any

from rl.a2cf.config import MODES, CoachHelpConfig, CurriculumConfig, WarmStartConfig, get_mode
from rl.config_bounds import check_range
from rl.envs.assist import DEFAULT_RANDOM_MASK_PROB
from rl.envs.config import EnvConfig
from rl.evaluation.config import AloneEvalConfig

if TYPE_CHECKING:
    from rl.a2cf.config import ModeSpec

MAX_ITERATIONS = 1_000_000_000
"""Most iterations a run may ask for (and the longest interval between kept checkpoints) [-]."""

MAX_NAME_BYTES = 255
"""Longest file or folder name Linux file systems take (a run folder's name, each part of --out)
[bytes]."""

MAX_ROLLOUT_TRANSITIONS = 2**24
"""Most transitions (envs x steps per env) one iteration may collect: a typical GPU run collects
4096 x 24 = 98,304; each transition stores about 3 kB of observations [-]."""


@dataclass(frozen=True)
class PPOConfig:
    """rsl-rl PPO hyper-parameters (rsl-rl / legged-gym defaults)."""

    learning_rate: float = 1e-3  # initial Adam learning rate (adaptive schedule) [-]
    num_learning_epochs: int | None = None  # PPO passes per rollout; None: the task's [-]
    num_mini_batches: int = 4  # mini-batches per pass [-]
    clip_param: float = 0.2  # PPO ratio clip [-]
    gamma: float | None = None  # discount per control step; None: the task's discount [-]
    lam: float = 0.95  # GAE lambda [-]
    value_loss_coef: float = 1.0  # weight of the value loss [-]
    entropy_coef: float = 0.005  # weight of the entropy bonus [-]
    max_grad_norm: float = 1.0  # gradient-norm clip [-]
    desired_kl: float = 0.01  # target KL of the adaptive learning-rate schedule [-]
    init_noise_std: float = 0.5  # initial std of the motion actions (raw action units) [-]
    kl_actions: str = "motion"  # whose KL sets the learning rate: "motion" or "all" [-]
    # the paper's is 1.0 (docs/training.md says why not)
    assist_init_noise_std: float = 0.3  # initial std of the raw assist actions, before tanh [-]
    # PPO's ratio and entropy over the assist actions "always" (rsl-rl's joint action, the paper's)
    # or "while_helping" (dropped once the curriculum has turned assistance off for good)
    assist_in_ratio: str = "always"  # assist actions in PPO's ratio: always, while_helping [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared (a saved config is checked on load too)."""
        check_range(self.learning_rate, "--ppo-learning-rate", 0.0, 1.0, low_open=True)
        if self.num_learning_epochs is not None:
            check_range(self.num_learning_epochs, "--ppo-num-learning-epochs", 1, 1000)
        check_range(self.num_mini_batches, "--ppo-num-mini-batches", 1)
        check_range(self.clip_param, "--ppo-clip-param", 0.0, 1.0, low_open=True)
        if self.gamma is not None:
            check_range(self.gamma, "--ppo-gamma", 0.0, 1.0, low_open=True)
        check_range(self.lam, "--ppo-lam", 0.0, 1.0)
        check_range(self.value_loss_coef, "--ppo-value-loss-coef", 0.0, 1000.0)
        check_range(self.entropy_coef, "--ppo-entropy-coef", 0.0, 100.0)
        check_range(self.max_grad_norm, "--ppo-max-grad-norm", 0.0, 1e6, low_open=True)
        check_range(self.desired_kl, "--ppo-desired-kl", 0.0, 1.0, low_open=True)
        # a std of 100 raw action units already drowns the policy's mean (actions are scaled
        # to joint offsets of a fraction of a radian)
        check_range(self.init_noise_std, "--ppo-init-noise-std", 0.0, 100.0, low_open=True)
        check_range(
            self.assist_init_noise_std, "--ppo-assist-init-noise-std", 0.0, 100.0, low_open=True
        )


@dataclass(frozen=True)
class ModelConfig:
    """Network sizes and the VAE loss weights (the one place these defaults live)."""

    motion_hidden_dims: tuple[int, ...] = (256, 128, 64)  # motion-head hidden layers [-]
    assist_hidden_dims: tuple[int, ...] = (128, 64)  # assist-head hidden layers [-]
    critic_hidden_dims: tuple[int, ...] = (256, 128, 64)  # critic hidden layers [-]
    encoder_hidden_dims: tuple[int, ...] = (128, 64)  # VAE encoder hidden layers [-]
    latent_dim: int = 16  # VAE latent size [-]
    activation: str = "elu"  # activation of every MLP [-]
    vae_learning_rate: float = 1e-3  # Adam learning rate of the history encoder [-]
    vae_kl_weight: float = 1e-3  # beta of the beta-VAE [-]
    vae_velocity_weight: float = 1.0  # weight of the velocity-estimation loss [-]
    vae_learning_epochs: int | None = None  # encoder passes per rollout; 0: PPO's; None: the task's

    def __post_init__(self) -> None:
        """Bound every numeric field where it is declared."""
        for name in ("motion", "assist", "critic", "encoder"):
            for width in getattr(self, f"{name}_hidden_dims"):
                check_range(width, f"--model-{name}-hidden-dims", 1, 100_000)
        check_range(self.latent_dim, "--model-latent-dim", 1, 100_000)
        check_range(self.vae_learning_rate, "--model-vae-learning-rate", 0.0, 1.0, low_open=True)
        check_range(self.vae_kl_weight, "--model-vae-kl-weight", 0.0, 1000.0)
        check_range(self.vae_velocity_weight, "--model-vae-velocity-weight", 0.0, 1000.0)
        if self.vae_learning_epochs is not None:
            check_range(self.vae_learning_epochs, "--model-vae-learning-epochs", 0, 1000)


@dataclass(frozen=True)
class TrainConfig:
    """One training run; nested configs become ``--env-*``, ``--ppo-*``, ``--model-*`` and
    ``--curriculum-*`` flags, task fields ``--task-*`` (see :mod:`a2cf_mb.commands.train`)."""

    task: str = "stand"  # registered task name (a2cf-mb list-tasks) [-]
    mode: str = field(default="a2cf", metadata={"help": " | ".join(MODES) + " [-]"})
    iterations: int = 100  # total learning iterations (a resume continues to it) [-]
    num_steps_per_env: int = 24  # control steps per env per iteration (rollout length) [-]
    out: str = "runs"  # parent folder of new run folders [-]
    run_name: str = ""  # run folder name; empty: <task>_<mode>_<UTC time> [-]
    resume: str = ""  # run folder to continue (last checkpoint); empty: a new run [-]
    # last.pt is written every iteration
    save_interval: int = 50  # iterations between kept checkpoints model_<it>.pt [-]
    random_mask_prob: float = DEFAULT_RANDOM_MASK_PROB  # zeta: a wrench component dropped [-]
    device: str = "cpu"  # torch device of the learner [-]
    torch_threads: int = 1  # torch intra-op threads; 0: torch's default [-]
    export_onnx: bool = True  # export the motion policy to ONNX at the end [-]
    random_episode_start: bool = True  # random initial episode counters (spread time-outs) [-]
    env: EnvConfig = field(default_factory=EnvConfig)  # env size, threads, seed, switches
    ppo: PPOConfig = field(default_factory=PPOConfig)  # PPO hyper-parameters
    model: ModelConfig = field(default_factory=ModelConfig)  # network sizes and VAE weights
    curriculum: CurriculumConfig = field(default_factory=CurriculumConfig)  # Algorithm 1
    eval: AloneEvalConfig = field(
        default_factory=AloneEvalConfig
    )  # evaluations of the motion policy alone during training
    # "posture": the built-in as-needed coach; an oracle artifact folder: its coach; empty: none
    warmstart: str = ""  # distil the assist head first from "posture" or an artifact [-]
    # from the task's time-indexed joint reference (dance)
    warmstart_motion: bool = False  # first clone the motion head from the joint reference [-]
    distill: WarmStartConfig = field(
        default_factory=WarmStartConfig
    )  # DAgger rounds of the warm start
    coach: CoachHelpConfig = field(
        default_factory=CoachHelpConfig
    )  # mode coach: the oracle artifact's coach as the help, scaled by the failure rate
    # clip files (LAFAN1 G1 CSV, NPZ, whole_body_tracking/mjlab motion NPZ), oracle artifact
    # folders or "builtin"
    reference: tuple[str, ...] = ()  # motions to track, one per episode; empty: the task's [-]
    reference_frames: str = ""  # frames A:B of every reference (B exclusive); empty: all [-]
    # solve-dance --clip's per-frame QP of the tracked segment (eta0 per 1 s bin), solved once
    # into <out>/oracle_cache/<fingerprint>/; --warmstart / --coach-source oracle then name it
    oracle: bool = False  # track: solve or reuse the reference's oracle artifact [-]
    # its torques feed --task-action-feedforward, its eta0 per bin an assist mode's curriculum
    oracle_artifact: str = ""  # oracle artifact folder the run uses (--oracle fills it) [-]
    task_overrides: dict[str, Any] = field(
        default_factory=dict
    )  # dotted task-field changes, see TaskConfig.with_overrides

    def __post_init__(self) -> None:
        """Check values a user could get wrong."""
        get_mode(self.mode)
        if self.torch_threads < 0:
            raise ValueError(
                f"--torch-threads must be >= 0 (0: torch's default), got {self.torch_threads}"
            )
        check_range(self.torch_threads, "--torch-threads", 0, 4096)
        for name in ("iterations", "num_steps_per_env", "save_interval"):
            if getattr(self, name) <= 0:
                raise ValueError(
                    f"--{name.replace('_', '-')} must be > 0, got {getattr(self, name)}"
                )
        # iteration counts are logged and saved as int32-sized numbers
        check_range(self.iterations, "--iterations", 1, MAX_ITERATIONS)
        check_range(self.save_interval, "--save-interval", 1, MAX_ITERATIONS)
        if not (self.device == "cpu" or re.fullmatch(r"cuda(:\d+)?", self.device)):
            raise ValueError(f"--device must be cpu, cuda or cuda:N, got '{self.device}'")
        for flag, path in (("--out", self.out), ("--run-name", self.run_name)):
            for part in PurePath(path).parts:
                if len(part.encode()) > MAX_NAME_BYTES:  # refused before any folder is made
                    raise ValueError(
                        f"{flag}: the folder name '{part[:24]}...' is {len(part.encode())} bytes "
                        f"long, more than the {MAX_NAME_BYTES} a file system allows: give a "
                        "shorter name"
                    )
        if self.ppo.kl_actions not in ("motion", "all"):
            raise ValueError(
                f"--ppo-kl-actions must be 'motion' or 'all', got '{self.ppo.kl_actions}'"
            )
        if self.ppo.assist_in_ratio not in ("while_helping", "always"):
            raise ValueError(
                f"--ppo-assist-in-ratio must be 'while_helping' or 'always', got "
                f"'{self.ppo.assist_in_ratio}'"
            )
        if not 0.0 <= self.random_mask_prob < 1.0:
            raise ValueError(f"--random-mask-prob must be in [0, 1), got {self.random_mask_prob}")
        if get_mode(self.mode).coach_help != bool(self.coach.source):
            raise ValueError(
                "mode 'coach' needs --coach-source ARTIFACT (the oracle artifact whose coach "
                "helps); --coach-source is only for mode 'coach'"
            )
        if self.warmstart and not get_mode(self.mode).assist:
            raise ValueError(
                f"--warmstart needs an assist head; mode '{self.mode}' has none (use a2cf)"
            )
        if (
            get_mode(self.mode).assist
            and self.curriculum.skill_measure == "evaluation"
            and self.eval.interval <= 0
        ):
            raise ValueError(
                "curriculum skill_measure 'evaluation' needs evaluations of the policy alone "
                "during training: set --eval-interval > 0, or --curriculum-skill-measure alone "
                "or helped"
            )
        batch = self.env.num_envs * self.num_steps_per_env
        if batch > MAX_ROLLOUT_TRANSITIONS:
            raise ValueError(
                f"--env-num-envs * --num-steps-per-env = {batch:,} transitions per iteration is "
                f"more than {MAX_ROLLOUT_TRANSITIONS:,} (the rollout storage alone would need "
                "tens of GB): give fewer envs or a shorter rollout"
            )
        if batch < self.ppo.num_mini_batches:
            raise ValueError(
                f"--env-num-envs * --num-steps-per-env = {batch} is smaller than "
                f"--ppo-num-mini-batches = {self.ppo.num_mini_batches}: give fewer mini-batches "
                "or a larger rollout"
            )

    @property
    def seed(self) -> int:
        """The run's seed (torch, numpy, random and the env): ``env.seed``."""
        return self.env.seed

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dictionary."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict` (lists back to tuples; unknown keys are an error)."""
        return _build(cls, data)


def _build(kind: type, values: dict[str, Any], where: str = "train") -> Any:
    """A dataclass from a JSON dictionary, recursing into nested dataclass fields; ``where``: the
    dotted path of ``values`` in the saved config (named in the errors)."""
    if not isinstance(values, dict):
        raise ValueError(f"{where} must be a JSON object, got {type(values).__name__}")
    hints = typing.get_type_hints(kind)
    names = {f.name for f in dataclasses.fields(kind)}
    unknown = sorted(set(values) - names)
    if unknown:
        fields = ", ".join(f"{where}.{name}" for name in unknown)
        raise ValueError(f"unknown field{'s' * (len(unknown) > 1)} {fields} ({kind.__name__})")
    kwargs: dict[str, Any] = {}
    for name, value in values.items():
        hint = hints[name]
        if dataclasses.is_dataclass(hint):
            value = _build(hint, value, f"{where}.{name}")
        elif typing.get_origin(hint) is tuple and isinstance(value, list):
            value = tuple(value)
        kwargs[name] = value
    try:
        return kind(**kwargs)
    except TypeError as err:  # a value of the wrong type, compared in a check
        raise ValueError(f"{where}: a field has a value of the wrong type ({err})") from err


def with_task_defaults(cfg: TrainConfig, task: Any) -> TrainConfig:
    """``cfg`` with PPO's discount and update epochs set: the run's own (``--ppo-gamma``,
    ``--ppo-num-learning-epochs``, ``--model-vae-learning-epochs``), else those of ``task`` (the run's resolved task)."""
    ppo, model = cfg.ppo, cfg.model
    if None in (ppo.gamma, ppo.num_learning_epochs, model.vae_learning_epochs):
        ppo = replace(
            ppo,
            gamma=task.discount if ppo.gamma is None else ppo.gamma,
            num_learning_epochs=(
                task.learning_epochs if ppo.num_learning_epochs is None else ppo.num_learning_epochs
            ),
        )
        vae = model.vae_learning_epochs
        model = replace(model, vae_learning_epochs=task.vae_learning_epochs if vae is None else vae)
    return replace(cfg, ppo=ppo, model=model)


def rsl_rl_config(cfg: TrainConfig, mode: ModeSpec) -> dict[str, Any]:
    """The rsl-rl runner configuration (class names, obs_groups, PPO and model kwargs)."""
    actor_groups = ["policy", "history"] + (
        ["privileged"] if mode.assist and mode.assist_privileged else []
    )
    if None in (cfg.ppo.gamma, cfg.ppo.num_learning_epochs, cfg.model.vae_learning_epochs):
        raise ValueError(
            "rsl_rl_config needs the task's defaults set: with_task_defaults(cfg, task)"
        )
    ppo = asdict(cfg.ppo)
    init_noise_std = ppo.pop("init_noise_std")
    assist_init_std = ppo.pop("assist_init_noise_std")
    kl_actions = ppo.pop("kl_actions")
    assist_in_ratio = ppo.pop("assist_in_ratio")
    return {
        "num_steps_per_env": cfg.num_steps_per_env,
        # rsl-rl calls save() every iteration: last.pt is always the latest state; the runner
        # keeps model_<k>.pt every cfg.save_interval iterations.
        "save_interval": 1,
        "obs_groups": {"actor": actor_groups, "critic": ["critic"]},
        "algorithm": {
            "class_name": "rl.agents.ppo:A2CFPPO",
            **ppo,
            "schedule": "adaptive",
            "vae_learning_rate": cfg.model.vae_learning_rate,
            "vae_kl_weight": cfg.model.vae_kl_weight,
            "vae_velocity_weight": cfg.model.vae_velocity_weight,
            "vae_learning_epochs": cfg.model.vae_learning_epochs,
        },
        "actor": {
            "class_name": "rl.agents.models:A2CFActor",
            "latent_dim": cfg.model.latent_dim,
            "encoder_hidden_dims": list(cfg.model.encoder_hidden_dims),
            "motion_hidden_dims": list(cfg.model.motion_hidden_dims),
            "assist_hidden_dims": list(cfg.model.assist_hidden_dims),
            "activation": cfg.model.activation,
            "obs_normalization": True,
            "assist_privileged": mode.assist_privileged,
            "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": init_noise_std},
            "assist_init_std": assist_init_std if mode.assist else None,
            "kl_motion_only": kl_actions == "motion",
            "assist_in_ratio_unhelped": assist_in_ratio == "always",
        },
        "critic": {
            "class_name": "MLPModel",
            "hidden_dims": list(cfg.model.critic_hidden_dims),
            "activation": cfg.model.activation,
            "obs_normalization": True,
        },
        "logger": "tensorboard",
        "check_for_nan": True,
    }
