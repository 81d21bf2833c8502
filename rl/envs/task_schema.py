"""The typed config of a task (the env's schema): everything a skill adds to the generic G1 env.

A task is one frozen :class:`TaskConfig` value (variants by :func:`dataclasses.replace`): its scene,
initial-state distribution, pushes and randomisation ranges, observation terms per group, reward
and termination terms, command generator, phase machine, skill measure and default assist bounds.
:class:`rl.envs.G1VecEnv` evaluates these; it never branches on which task it runs. A new task is
one module defining such a value plus a line in :mod:`rl.tasks.registry`.

It lives beside the env, with the term types (:mod:`rl.envs.terms`) and the component protocols
(:mod:`rl.envs.components`), so that ``rl.envs`` imports nothing from ``rl.tasks``; task modules
import these names from here.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import mujoco
import torch

from rl.config_bounds import check_pair, check_range
from rl.envs.components import NoCommandConfig, SinglePhaseConfig, SurvivalSkillConfig
from rl.envs.terms import ObsGroup, RewardTerm, TerminationTerm, check_unique

ResetStateFn = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, torch.Generator], None]
"""``fn(env_ids (M,), qpos (M, 36), qvel (M, 35), generator)``: edit the float64 MuJoCo initial
state of resetting envs in place (e.g. start from a reference frame)."""
TerrainFn = Callable[[mujoco.MjSpec], None]
"""``fn(spec)``: add terrain geoms to the physics spec (contype 1, conaffinity 3 like the floor)."""

MAX_PUSH_MPS = 20.0
"""Largest push velocity a task accepts: a kick of more than 20 m/s is no disturbance a robot
could meet [m/s]."""


@dataclass(frozen=True)
class SceneConfig:
    """What the robot stands on and which of its geoms collide."""

    floor: bool = True  # a ground plane at z = 0
    link_collisions: bool = True  # fitted link capsules/boxes collide with floor and terrain
    terrain: TerrainFn | None = None  # adds terrain geoms to the spec; None: floor only
    tracked_bodies: tuple[str, ...] = ()  # links whose pose and velocity EnvState.body_* hold [-]


@dataclass(frozen=True)
class InitialStateConfig:
    """The distribution of the state an episode starts from (around the standing keyframe)."""

    joint_pos_noise_rad: float = 0.05  # uniform +- offset of each joint from the stand pose [rad]
    base_vel_noise: float = 0.1  # uniform +- base linear [m/s] and angular [rad/s] velocity
    random_yaw: bool = True  # uniform random base heading
    reset_state: ResetStateFn | None = None  # task hook applied after the noise; None: none

    def __post_init__(self) -> None:
        """Bound the noise where it is declared; ``--task-initial-state-*`` are its flags."""
        check_range(
            self.joint_pos_noise_rad, "--task-initial-state-joint-pos-noise-rad", 0.0, math.pi
        )
        check_range(self.base_vel_noise, "--task-initial-state-base-vel-noise", 0.0, 10.0)


@dataclass(frozen=True)
class PushConfig:
    """Random pushes: horizontal base velocity kicks at random intervals."""

    enabled: bool = True  # push the robots
    interval_range_s: tuple[float, float] = (3.0, 6.0)  # time between two pushes [s]
    velocity_xy_mps: float = 0.5  # largest +- horizontal base velocity change of a push [m/s]
    # evaluations of the policy alone always push at velocity_xy_mps, so training can push harder
    # than the skill is judged at
    train_velocity_xy_mps: float = 0.0  # largest push while training; 0: velocity_xy_mps [m/s]
    # the kick's forward component in the robot's heading frame made negative (evaluations
    # never): stand's and walk-flat's falls are backward kicks
    train_backward_share: float = 0.0  # share of training kicks turned backwards [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared; ``--task-pushes-*`` are its flags."""
        # an interval is a count of control steps: an hour is more than any episode
        check_pair(
            self.interval_range_s, "--task-pushes-interval-range-s", 0.0, 3600.0, low_open=True
        )
        check_range(self.train_backward_share, "--task-pushes-train-backward-share", 0.0, 1.0)
        check_range(self.velocity_xy_mps, "--task-pushes-velocity-xy-mps", 0.0, MAX_PUSH_MPS)
        check_range(
            self.train_velocity_xy_mps, "--task-pushes-train-velocity-xy-mps", 0.0, MAX_PUSH_MPS
        )


@dataclass(frozen=True)
class RandomizationConfig:
    """Domain randomisation ranges, drawn per env (see ``model_groups`` for the memory trade)."""

    enabled: bool = True  # randomise friction, payload and CoM offset
    friction_range: tuple[float, float] = (0.4, 1.25)  # sole and floor sliding friction [-]
    payload_mass_range_kg: tuple[float, float] = (-1.0, 3.0)  # mass added to the payload body [kg]
    com_offset_range_m: tuple[float, float] = (-0.03, 0.03)  # payload-body CoM shift per axis [m]
    payload_body: str = "torso_link"  # body receiving payload and CoM offset (MuJoCo name)
    # 0: one model copy per env, redrawn at each reset
    model_groups: int = 0  # G model copies drawn once, env i uses i % G; 0: per env [-]

    def __post_init__(self) -> None:
        """Bound every field where it is declared; ``--task-randomization-*`` are its flags."""
        flag = "--task-randomization-"
        check_pair(self.friction_range, flag + "friction-range", 0.0, 10.0, low_open=True)
        check_pair(self.payload_mass_range_kg, flag + "payload-mass-range-kg", -100.0, 100.0)
        check_pair(self.com_offset_range_m, flag + "com-offset-range-m", -1.0, 1.0)
        check_range(self.model_groups, flag + "model-groups", 0, 1_000_000)


@dataclass(frozen=True)
class ObservationsConfig:
    """Observation terms of the three task-defined groups.

    The env derives three more: ``policy_clean`` (the policy terms without noise), ``history``
    (the last H noisy policy observations) and ``base_lin_vel`` (the VAE's velocity target).
    """

    policy: ObsGroup  # what the deployed motion policy reads (noisy)
    privileged: ObsGroup  # what only the assist head (and critic) read in simulation
    critic: ObsGroup  # the critic's full state


@dataclass(frozen=True)
class SkillTarget:
    """What the motion policy *alone* (assistance off, fresh envs, one episode each) must reach
    for the skill to count as learned: a survival share and, optionally, one task metric of the
    task's evaluator at or below a bound."""

    min_survival: float = 0.9  # share of evaluation episodes that must not fail [-]
    metric: str = ""  # evaluator metric held below max_metric; empty: none
    max_metric: float = 0.0  # the metric's upper bound, in its unit

    def __post_init__(self) -> None:
        """A survival share is a probability; ``--task-target-*`` are its flags."""
        check_range(self.min_survival, "--task-target-min-survival", 0.0, 1.0)
        check_range(self.max_metric, "--task-target-max-metric", 0.0, 1e6)

    def reached(self, result: dict[str, Any]) -> bool:
        """Whether an evaluation result (``survival_fraction``, ``task_metrics``) meets it."""
        if result["survival_fraction"] < self.min_survival:
            return False
        if not self.metric:
            return True
        value = result.get("task_metrics", {}).get(self.metric)
        return value is not None and value <= self.max_metric

    def progress(self, result: dict[str, Any]) -> float:
        """How close an evaluation result is to the target, >= 1 where :meth:`reached`: the
        smaller of ``survival / min_survival`` and ``max_metric / metric`` (0 for a missing
        metric)."""
        ratios = [result["survival_fraction"] / self.min_survival] if self.min_survival else []
        if self.metric:
            value = result.get("task_metrics", {}).get(self.metric)
            ratios.append(0.0 if value is None else self.max_metric / max(value, 1e-9))
        return float(min(ratios, default=1.0))

    def describe(self) -> str:
        """One line, e.g. ``survival >= 0.9 and lin_vel_error_mps <= 0.25``."""
        text = f"survival >= {self.min_survival:g}"
        return text + (f" and {self.metric} <= {self.max_metric:g}" if self.metric else "")


@dataclass(frozen=True)
class TaskConfig:
    """One skill for the G1 env (see the module docstring)."""

    name: str  # registry name [-]
    description: str  # one line for ``a2cf-mb list-tasks``
    observations: ObservationsConfig  # observation terms per group
    rewards: tuple[RewardTerm, ...]  # weighted reward terms, each named once
    terminations: tuple[TerminationTerm, ...]  # failure conditions
    assist_bound: tuple[tuple[float, ...], ...]  # default eta0, one 6-D row per phase [N, Nm]
    episode_length_s: float = 10.0  # episode duration before a time-out [s]
    scene: SceneConfig = field(default_factory=SceneConfig)  # floor, terrain, colliding geoms
    initial_state: InitialStateConfig = field(
        default_factory=InitialStateConfig
    )  # reset distribution
    pushes: PushConfig = field(default_factory=PushConfig)  # random base kicks
    randomization: RandomizationConfig = field(default_factory=RandomizationConfig)  # domain ranges
    commands: Any = field(default_factory=NoCommandConfig)  # command generator config (has build)
    phases: Any = field(
        default_factory=SinglePhaseConfig
    )  # phase machine config (has names, build)
    skill: Any = field(default_factory=SurvivalSkillConfig)  # skill-progress config (has build)
    less_assist_weight: float = 1.0  # weight of the less-assist reward once switched on [-]
    oracle_tasks: tuple[str, ...] = ()  # tasks whose solve-* artifacts also warm-start this one [-]
    # Not around the standing pose: zero action follows the reference (a tracking task's command
    # must give it).
    actions_around_reference: bool = False  # PD targets around the reference, q_ref + scale a
    # With actions_around_reference: tau = kp (q_ref - q) + kd (qd_ref - qd) + tau_ref + kp scale a
    # (the target shifted by kd/kp qd_ref + tau_ref/kp): zero action is the oracle's own control.
    action_feedforward: bool = False  # feed-forward of the reference's joint rates and torques
    # A tracking task's drift terminations (anchor tilt, end-effector height), e.g. in a flip's
    # flight: jump air (a rotation running behind the reference is then caught up or landed, not
    # cut off).
    drift_free_phases: tuple[str, ...] = ()  # phases in which drift terminations end no episode [-]
    evaluation: Any = None  # task-specific eval config (build(env) -> evaluator); None: generic
    target: SkillTarget = field(default_factory=SkillTarget)  # the assistance-free skill target
    # The task's own PPO update, used where the run gives none (--ppo-gamma, ...):
    discount: float = 0.99  # PPO's discount per control step [-]
    learning_epochs: int = 5  # PPO passes over each rollout [-]
    vae_learning_epochs: int = 0  # history-encoder passes over each rollout; 0 = PPO's [-]

    def __post_init__(self) -> None:
        check_unique("reward", self.rewards)
        check_unique("termination", self.terminations)
        for group in ("policy", "privileged", "critic"):
            check_unique(f"{group} observation", getattr(self.observations, group).terms)
        check_range(self.discount, "--task-discount", 0.0, 1.0, low_open=True)
        if self.drift_free_phases and not any("free_phases" in t.params for t in self.terminations):
            raise ValueError(
                f"task '{self.name}' has no drift termination to switch off by phase; "
                "--task-drift-free-phases is for the tracking tasks (--task track)"
            )
        check_range(self.learning_epochs, "--task-learning-epochs", 1, 1000)
        check_range(self.vae_learning_epochs, "--task-vae-learning-epochs", 0, 1000)
        # a day of control steps still fits the int32 step counters
        check_range(self.episode_length_s, "--task-episode-length-s", 0.0, 86_400.0, low_open=True)
        check_range(self.less_assist_weight, "--task-less-assist-weight", 0.0, 1000.0)
        rows = self.assist_bound
        if len(rows) != len(self.phase_names) or any(len(r) != 6 for r in rows):
            raise ValueError(
                f"task '{self.name}': assist_bound needs one 6-D row per phase "
                f"({len(self.phase_names)} phases), got {rows}"
            )

    @property
    def phase_names(self) -> tuple[str, ...]:
        """Names of the task phases (one assist-bound row each)."""
        return tuple(self.phases.names)

    @property
    def num_phases(self) -> int:
        """Number of phases P."""
        return len(self.phase_names)

    def default_assist_bound(self) -> torch.Tensor:
        """eta0 (P, 6) [N, Nm] when no oracle artifact gives one."""
        return torch.tensor(self.assist_bound, dtype=torch.float32)

    def with_reward_weights(self, weights: dict[str, float]) -> TaskConfig:
        """A variant with some reward weights replaced (unknown names: a clear error)."""
        names = {t.name for t in self.rewards}
        unknown = sorted(set(weights) - names)
        if unknown:
            raise ValueError(
                f"task '{self.name}' has no reward term {unknown}; its terms: {sorted(names)}"
            )
        return dataclasses.replace(
            self,
            rewards=tuple(
                dataclasses.replace(t, weight=float(weights[t.name])) if t.name in weights else t
                for t in self.rewards
            ),
        )

    def with_term_params(self, params: dict[str, dict[str, Any]]) -> TaskConfig:
        """A variant with term parameters replaced: ``{term_name: {param: value}}``.

        Applies to reward, termination and observation terms of that name; a parameter the term
        does not already have is refused (it would be silently ignored by nothing, or crash later).
        """
        found: set[str] = set()

        def edit(term):
            if term.name not in params:
                return term
            missing = sorted(set(params[term.name]) - set(term.params))
            if missing:
                raise ValueError(
                    f"term '{term.name}' of task '{self.name}' has no parameter {missing}; "
                    f"its parameters: {sorted(term.params)}"
                )
            found.add(term.name)
            return dataclasses.replace(term, params={**term.params, **params[term.name]})

        def group(g: ObsGroup) -> ObsGroup:
            return dataclasses.replace(g, terms=tuple(edit(t) for t in g.terms))

        obs = self.observations
        variant = dataclasses.replace(
            self,
            rewards=tuple(edit(t) for t in self.rewards),
            terminations=tuple(edit(t) for t in self.terminations),
            observations=ObservationsConfig(
                policy=group(obs.policy), privileged=group(obs.privileged), critic=group(obs.critic)
            ),
        )
        unknown = sorted(set(params) - found)
        if unknown:
            raise ValueError(f"task '{self.name}' has no term named {unknown}")
        return variant

    def with_overrides(self, overrides: dict[str, Any]) -> TaskConfig:
        """A variant from CLI-style changes (what ``TrainConfig.task_overrides`` stores):

        - ``"reward_weights": {term: weight}`` (see :meth:`with_reward_weights`);
        - ``"term_params": {term: {param: value}}`` (see :meth:`with_term_params`);
        - ``"a.b": value``: the (nested) scalar field ``a.b``, e.g. ``"pushes.velocity_xy_mps"``.
        """
        task = self
        for key, value in overrides.items():
            if key == "reward_weights":
                task = task.with_reward_weights(value)
            elif key == "term_params":
                task = task.with_term_params(value)
            else:
                task = _replace_path(task, key.split("."), value, key)
        return task

    def to_json_dict(self) -> dict[str, Any]:
        """The resolved config as JSON-ready data (functions by their qualified name)."""
        import json

        def name_of(obj: Any) -> str:
            if callable(obj):
                return (
                    f"{getattr(obj, '__module__', '?')}.{getattr(obj, '__qualname__', repr(obj))}"
                )
            return repr(obj)

        return json.loads(json.dumps(dataclasses.asdict(self), default=name_of))


def _replace_path(obj: Any, path: list[str], value: Any, key: str) -> Any:
    """``obj`` with the field at ``path`` (nested dataclasses) set to ``value``."""
    names = {f.name for f in dataclasses.fields(obj)}
    head = path[0]
    if head not in names:
        raise ValueError(
            f"task override '{key}': {type(obj).__name__} has no field '{head}' "
            f"(fields: {sorted(names)})"
        )
    if len(path) == 1:
        current = getattr(obj, head)
        if isinstance(current, tuple) and isinstance(value, list):
            value = tuple(value)
        return dataclasses.replace(obj, **{head: value})
    child = getattr(obj, head)
    if not dataclasses.is_dataclass(child):
        raise ValueError(f"task override '{key}': '{head}' is not a nested config")
    return dataclasses.replace(obj, **{head: _replace_path(child, path[1:], value, key)})


def quiet(task: TaskConfig) -> TaskConfig:
    """A variant whose physics depends only on the actions: no pushes, randomisation, reset
    noise or observation noise (tests, debugging, deterministic replays)."""
    obs = task.observations
    return dataclasses.replace(
        task,
        pushes=dataclasses.replace(task.pushes, enabled=False),
        randomization=dataclasses.replace(task.randomization, enabled=False),
        initial_state=dataclasses.replace(
            task.initial_state, joint_pos_noise_rad=0.0, base_vel_noise=0.0, random_yaw=False
        ),
        observations=dataclasses.replace(obs, policy=dataclasses.replace(obs.policy, noisy=False)),
    )
