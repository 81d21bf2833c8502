"""``walk``: follow a velocity command on rough terrain (the paper's walking task).

Commands (vx, vy, yaw rate) are drawn uniformly (vx in [-0.6, 1.2] m/s, vy up to 0.8 m/s, yaw rate up
to 1.5 rad/s), resampled every 4-8 s, a share of envs told to stand. Robots start in the centre of a
tile of their terrain level (:mod:`rl.tasks.terrain`: flat, slopes, rough, obstacles, stairs, 10
levels, top stair 0.23 m); at the end of an episode a robot that walked off its tile (more than half
a tile from its start) is promoted, one that walked less than half its commanded distance demoted,
and a robot promoted past the top level is sent to a random level (Isaac Lab's terrain
curriculum; the paper's mean level then settles near 6). Skill progress = mean level over
``learned_fraction`` of the top level. Rewards: the paper's walking table, term for term.
The height scan (1.6 m x 1.0 m at 0.1 m around the pelvis) is privileged (assist head, critic).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import torch

from rl import rewards, terminations
from rl.curriculum import paper_bound_rows
from rl.envs.state import EnvState
from rl.tasks import walk_terms
from rl.tasks.components import (
    Command,
    CommandColumns,
    SinglePhaseConfig,
    SkillMeasure,
    SurvivalSkillConfig,
)
from rl.tasks.config import (
    ObservationsConfig,
    PushConfig,
    RandomizationConfig,
    SceneConfig,
    SkillTarget,
    TaskConfig,
)
from rl.tasks.stand import CRITIC_EXTRA, PRIVILEGED, PROPRIOCEPTION, STAND_OBSERVATIONS
from rl.tasks.terms import ObsGroup, ObsTerm, RewardTerm, TerminationTerm
from rl.tasks.terrain import Terrain, TerrainConfig
from rl.tasks.walk_eval import WalkEvaluationConfig
from robots import g1

WALK_TERRAIN = Terrain(TerrainConfig())
"""The walk task's terrain (built on first use), shared by scene, curriculum and height scan."""


# ------------------------------------------------------------------------------------ command
@dataclass(frozen=True)
class VelocityCommandConfig:
    """Uniform velocity commands in the pelvis frame, resampled within the episode; optionally a
    gait clock (appended to the command) and a command curriculum (ranges widened while the
    robots track)."""

    lin_vel_x_range_mps: tuple[float, float] = (-0.6, 1.2)  # forward velocity [m/s]
    lin_vel_y_range_mps: tuple[float, float] = (-0.8, 0.8)  # lateral velocity [m/s]
    ang_vel_z_range_rps: tuple[float, float] = (-1.5, 1.5)  # yaw rate [rad/s]
    resampling_time_range_s: tuple[float, float] = (4.0, 8.0)  # time between two draws [s]
    standing_fraction: float = 0.1  # share of draws that command standing still (zeros) [-]
    gait_period_s: float = 0.0  # period of the gait clock appended as (sin, cos); 0: no clock [s]
    curriculum_initial_scale: float = 1.0  # ranges start at this fraction of the above [-]
    curriculum_error_mps: float = 0.25  # ranges widen while the mean velocity error is below [m/s]
    curriculum_rate_per_s: float = 0.01  # widening of the scale per second of env time [1/s]

    def __post_init__(self) -> None:
        for name in (
            "lin_vel_x_range_mps",
            "lin_vel_y_range_mps",
            "ang_vel_z_range_rps",
            "resampling_time_range_s",
        ):
            low, high = getattr(self, name)
            if low > high:
                raise ValueError(f"velocity command {name} must be (low, high), got {(low, high)}")
        if self.resampling_time_range_s[0] <= 0:
            raise ValueError("velocity command resampling_time_range_s must be > 0 s")
        if not 0.0 <= self.standing_fraction <= 1.0:
            raise ValueError(
                f"velocity command standing_fraction must be in [0, 1], got {self.standing_fraction}"
            )
        if self.gait_period_s < 0:
            raise ValueError(
                f"velocity command gait_period_s must be >= 0, got {self.gait_period_s}"
            )
        if not 0.0 < self.curriculum_initial_scale <= 1.0:
            raise ValueError(
                "velocity command curriculum_initial_scale must be in (0, 1], got "
                f"{self.curriculum_initial_scale}"
            )

    @property
    def dim(self) -> int:
        """Command width C: vx, vy, yaw rate (+ sin, cos of the gait clock) [-]."""
        return 5 if self.gait_period_s > 0 else 3

    def build(self, num_envs: int, generator: torch.Generator) -> VelocityCommand:
        """The live command generator (draws from the env's generator)."""
        return VelocityCommand(self, num_envs, generator)


class VelocityCommand(Command):
    """Per-env (vx, vy, yaw rate) with a countdown to the next draw, the gait clock and the
    command curriculum's scale; see the config."""

    def __init__(self, cfg: VelocityCommandConfig, num_envs: int, generator: torch.Generator):
        self.cfg = cfg
        self.generator = generator
        self.command = torch.zeros(num_envs, cfg.dim)
        self.time_left_s = torch.zeros(num_envs)
        self.clock_s = torch.zeros(num_envs)  # time since the episode's start [s]
        self.scale = torch.tensor(cfg.curriculum_initial_scale)  # command curriculum [-]
        self.error_mps = torch.tensor(0.0)  # running mean velocity error (0.5 s time constant)
        ranges = (cfg.lin_vel_x_range_mps, cfg.lin_vel_y_range_mps, cfg.ang_vel_z_range_rps)
        self._low = torch.tensor([r[0] for r in ranges])
        self._high = torch.tensor([r[1] for r in ranges])

    def resample(self, env_ids: torch.Tensor) -> None:
        """Draw new commands and countdowns for ``env_ids`` (M,) within the scaled ranges."""
        m, gen = env_ids.numel(), self.generator
        if m == 0:
            return
        low, high = self._low * self.scale, self._high * self.scale
        draw = low + (high - low) * torch.rand(m, 3, generator=gen)
        standing = torch.rand(m, generator=gen) < self.cfg.standing_fraction
        self.command[env_ids, :3] = torch.where(standing[:, None], torch.zeros_like(draw), draw)
        t_low, t_high = self.cfg.resampling_time_range_s
        self.time_left_s[env_ids] = t_low + (t_high - t_low) * torch.rand(m, generator=gen)

    def reset(self, env_ids: torch.Tensor) -> None:
        """A new episode starts with a new command and the clock at 0."""
        self.resample(env_ids)
        self.clock_s[env_ids] = 0.0
        self._write_clock()

    def _write_clock(self) -> None:
        if self.cfg.gait_period_s > 0:
            angle = 2 * torch.pi * (self.clock_s / self.cfg.gait_period_s % 1.0)
            self.command[:, 3] = torch.sin(angle)
            self.command[:, 4] = torch.cos(angle)

    def compute(self, state: EnvState, dt_s: float) -> torch.Tensor:
        """Count down by ``dt_s`` [s], redraw the expired commands, advance the clock and the
        curriculum; (N, C)."""
        cfg = self.cfg
        if dt_s > 0 and self.scale < 1.0:
            error = (state.base_lin_vel_b[:, :2] - self.command[:, :2]).norm(dim=-1).mean()
            self.error_mps += (error - self.error_mps) * min(dt_s / 0.5, 1.0)
            if self.error_mps < cfg.curriculum_error_mps:
                self.scale = (self.scale + cfg.curriculum_rate_per_s * dt_s).clamp(max=1.0)
        self.time_left_s -= dt_s
        self.resample((self.time_left_s <= 0).nonzero().flatten())
        self.clock_s += dt_s
        self._write_clock()
        return self.command

    def columns(self) -> tuple[CommandColumns, ...]:
        """Velocity (vx, vy, yaw rate) in the pelvis frame, then the gait clock (sin, cos)."""
        blocks = (
            CommandColumns("lin_vel_x", 1, "m/s", "forward velocity to walk at, pelvis frame"),
            CommandColumns("lin_vel_y", 1, "m/s", "lateral velocity (left positive), pelvis frame"),
            CommandColumns("ang_vel_z", 1, "rad/s", "yaw rate (counter-clockwise positive)"),
        )
        if self.cfg.gait_period_s > 0:
            blocks += (
                CommandColumns(
                    "gait_clock", 2, "-",
                    f"sin, cos of 2 pi t / {self.cfg.gait_period_s:g} s, t: time since the "
                    "policy started [s] (the left foot's gait phase; the right foot is half a "
                    "period later)",
                ),
            )  # fmt: skip
        return blocks

    def for_evaluation(self) -> None:
        """Evaluations draw from the full command ranges."""
        self.scale = torch.tensor(1.0)

    def log(self) -> dict[str, float]:
        """``Curriculum/command_scale`` (when the curriculum is on)."""
        return (
            {"Curriculum/command_scale": float(self.scale)}
            if self.cfg.curriculum_initial_scale < 1
            else {}
        )

    def state_dict(self) -> dict[str, Any]:
        """Commands, countdowns, clocks and the curriculum."""
        return {
            "command": self.command.clone(),
            "time_left_s": self.time_left_s.clone(),
            "clock_s": self.clock_s.clone(),
            "scale": self.scale.clone(),
            "error_mps": self.error_mps.clone(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.command.copy_(state["command"])
        self.time_left_s.copy_(state["time_left_s"])
        self.clock_s.copy_(state["clock_s"])
        self.scale = state["scale"].clone()
        self.error_mps = state["error_mps"].clone()


# --------------------------------------------------------------------- terrain curriculum
@dataclass(frozen=True)
class TerrainCurriculumConfig:
    """Terrain-level curriculum and the walk skill measure (see the module docstring)."""

    terrain: Terrain = WALK_TERRAIN  # the terrain the envs are placed on
    max_init_level: int = 0  # first levels are drawn uniformly in [0, max_init_level] [-]
    promote_tile_fraction: float = 0.5  # promote when the distance walked exceeds this x tile [-]
    demote_command_fraction: float = 0.5  # demote below this x commanded distance [-]
    learned_fraction: float = 0.6  # skill learned at mean level = this x top level [-]
    seed: int = 0  # generator of the random levels of top-level solvers [-]

    def __post_init__(self) -> None:
        if not 0 <= self.max_init_level < self.terrain.num_rows:
            raise ValueError(
                f"terrain curriculum max_init_level must be in [0, {self.terrain.num_rows - 1}], "
                f"got {self.max_init_level}"
            )
        if not 0.0 < self.learned_fraction <= 1.0:
            raise ValueError(
                f"terrain curriculum learned_fraction must be in (0, 1], got {self.learned_fraction}"
            )

    def build(self, max_episode_length: int) -> TerrainCurriculum:
        """The live curriculum for episodes of ``max_episode_length`` policy steps."""
        return TerrainCurriculum(self, max_episode_length)


class TerrainCurriculum(SkillMeasure):
    """Per-env terrain level and tile; places resetting robots on their tile (``reset_state``)
    and moves levels at episode ends. Per-env tensors are sized at the env's first reset (which
    resets every env), as the build hook does not receive the number of envs."""

    def __init__(self, cfg: TerrainCurriculumConfig, max_episode_length: int) -> None:
        self.cfg = cfg
        self.terrain = cfg.terrain
        self.max_episode_length = max_episode_length
        self.top_level = cfg.terrain.num_rows - 1
        self.levels = torch.zeros(0, dtype=torch.long)  # (N,) terrain level (row) [-]
        self.cols = torch.zeros(0, dtype=torch.long)  # (N,) tile column of this episode [-]
        self.spawn_xy_w = torch.zeros(0, 2)  # (N, 2) start position of this episode [m]
        self.placed = torch.zeros(0, dtype=torch.bool)  # (N,) level drawn already
        self.fixed_tiles: torch.Tensor | None = None  # (N, 2) (row, col) pinned (evaluation)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.promotions = 0
        self.demotions = 0

    def _ensure(self, size: int) -> None:
        grow = size - self.levels.numel()
        if grow > 0:
            self.levels = torch.cat([self.levels, torch.zeros(grow, dtype=torch.long)])
            self.cols = torch.cat([self.cols, torch.zeros(grow, dtype=torch.long)])
            self.spawn_xy_w = torch.cat([self.spawn_xy_w, torch.zeros(grow, 2)])
            self.placed = torch.cat([self.placed, torch.zeros(grow, dtype=torch.bool)])

    def pin_tiles(self, tiles: torch.Tensor | None) -> None:
        """Pin env i to tile ``tiles[i]`` = (row, col) at its next resets (None: unpin)."""
        self.fixed_tiles = None if tiles is None else tiles.long().clone()

    def reset_state(
        self,
        env_ids: torch.Tensor,
        qpos: torch.Tensor,
        qvel: torch.Tensor,
        generator: torch.Generator,
    ) -> None:
        """Move resetting robots to the centre of a tile of their level (random column),
        raised by the tile's spawn height."""
        self._ensure(int(env_ids.max()) + 1)
        m = env_ids.numel()
        new = env_ids[~self.placed[env_ids]]
        if new.numel():
            high = self.cfg.max_init_level + 1
            self.levels[new] = torch.randint(0, high, (new.numel(),), generator=generator)
            self.placed[new] = True
        self.cols[env_ids] = torch.randint(0, self.terrain.num_cols, (m,), generator=generator)
        if self.fixed_tiles is not None:
            self.levels[env_ids] = self.fixed_tiles[env_ids, 0]
            self.cols[env_ids] = self.fixed_tiles[env_ids, 1]
        rows, cols = self.levels[env_ids], self.cols[env_ids]
        centre = self.terrain.tile_center_xy(rows, cols)
        qpos[:, 0:2] = centre.double()
        qpos[:, 2] += self.terrain.spawn_height_m[rows, cols].double()
        self.spawn_xy_w[env_ids] = centre

    def distance_walked_m(self, env_ids: torch.Tensor, state: EnvState) -> torch.Tensor:
        """Horizontal distance (M,) [m] of ``env_ids`` from their episode's start."""
        return (state.base_pos_w[env_ids, :2] - self.spawn_xy_w[env_ids]).norm(dim=-1)

    def update_levels(
        self, env_ids: torch.Tensor, distance_m: torch.Tensor, required_m: torch.Tensor
    ) -> None:
        """Promote ``env_ids`` (M,) that walked more than the promotion distance, demote those
        that walked less than ``required_m`` (M,) [m]; past the top: a random level."""
        promote = distance_m > self.cfg.promote_tile_fraction * self.terrain.cfg.tile_size_m
        demote = (distance_m < required_m) & ~promote
        levels = self.levels[env_ids] + promote.long() - demote.long()
        solved = levels > self.top_level
        random_levels = torch.randint(
            0, self.top_level + 1, (env_ids.numel(),), generator=self.generator
        )
        self.levels[env_ids] = torch.where(solved, random_levels, levels.clamp_min(0))
        self.promotions += int(promote.sum())
        self.demotions += int(demote.sum())

    def on_episodes_end(
        self,
        env_ids: torch.Tensor,
        time_outs: torch.Tensor,
        lived_steps: torch.Tensor,
        state: EnvState,
    ) -> None:
        """Move the levels of finished episodes: commanded distance = |v_xy^cmd| x the episode
        duration (the lived time for time-outs, the full episode for falls)."""
        distance = self.distance_walked_m(env_ids, state)
        steps = torch.where(
            time_outs, lived_steps, torch.full_like(lived_steps, self.max_episode_length)
        )
        duration_s = steps.float() * state.step_dt_s
        required = (
            self.cfg.demote_command_fraction * state.command[env_ids, :2].norm(dim=-1) * duration_s
        )
        self.update_levels(env_ids, distance, required)

    def mean_level(self) -> float:
        """Mean terrain level of the envs [-]."""
        return float(self.levels.float().mean()) if self.levels.numel() else 0.0

    def progress(self) -> float:
        """Mean level over ``learned_fraction`` x top level."""
        return self.mean_level() / (self.cfg.learned_fraction * self.top_level)

    def log(self) -> dict[str, float]:
        """``Curriculum/terrain_level`` (mean), its max and the share of envs per level."""
        if not self.levels.numel():
            return {}
        counts = torch.bincount(self.levels, minlength=self.top_level + 1).float()
        share = counts / self.levels.numel()
        out = {
            "Curriculum/terrain_level": self.mean_level(),
            "Curriculum/terrain_level_max": float(self.levels.max()),
        }
        for level, value in enumerate(share.tolist()):
            out[f"Curriculum/terrain_level_share_{level}"] = value
        return out

    def state_dict(self) -> dict[str, Any]:
        """Levels, tiles, starts and the generator."""
        return {
            "levels": self.levels.clone(),
            "cols": self.cols.clone(),
            "spawn_xy_w": self.spawn_xy_w.clone(),
            "placed": self.placed.clone(),
            "generator": self.generator.get_state(),
            "promotions": self.promotions,
            "demotions": self.demotions,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` output."""
        self.levels = state["levels"].clone()
        self.cols = state["cols"].clone()
        self.spawn_xy_w = state["spawn_xy_w"].clone()
        self.placed = state["placed"].clone()
        self.generator.set_state(state["generator"])
        self.promotions = int(state["promotions"])
        self.demotions = int(state["demotions"])


# ------------------------------------------------------------------------------------- task
HEIGHT_SCAN = ObsTerm(
    "height_scan",
    walk_terms.height_scan,
    params={"terrain": WALK_TERRAIN, "size_m": (1.6, 1.0), "resolution_m": 0.1},
)
"""Privileged height scan: 17 x 11 points around the pelvis (187 values) [m]."""

WALK_OBSERVATIONS = ObservationsConfig(
    policy=ObsGroup(PROPRIOCEPTION, noisy=True),
    privileged=ObsGroup(PRIVILEGED + (HEIGHT_SCAN,)),
    critic=ObsGroup(PROPRIOCEPTION + PRIVILEGED + (HEIGHT_SCAN,) + CRITIC_EXTRA),
)


_WALK_PAPER_REWARDS = (
    RewardTerm("track_lin_vel_xy", walk_terms.track_lin_vel_xy_exp, weight=5.0),
    RewardTerm("track_ang_vel_z", walk_terms.track_ang_vel_z_exp, weight=2.0),
    RewardTerm("feet_air_time", walk_terms.feet_air_time, weight=1.0),
    RewardTerm("feet_slide", rewards.feet_slide, weight=-1.0),
    RewardTerm("cost_of_transport", walk_terms.cost_of_transport, weight=-0.01),
    RewardTerm("stand_still", walk_terms.stand_still, weight=-0.1),
    RewardTerm("action_rate", rewards.action_rate_l2, weight=-0.01),
    RewardTerm("joint_acc", rewards.joint_acc_l2, weight=-2.5e-7),
    RewardTerm("joint_pos_limits", rewards.joint_pos_limits, weight=-1.0),
    RewardTerm("orientation", rewards.orientation_l2, weight=-1.0),
)
"""The paper's walking reward table, term for term (no survival term: falling pays, see
``docs/environments.md``)."""

UPPER_BODY_JOINTS = tuple(
    name for name in g1.JOINT_NAMES if name.startswith(("waist", "left_s", "left_e", "left_w",
                                                         "right_s", "right_e", "right_w"))
)  # fmt: skip
"""Waist and arm joints (held near the default pose by the walk's pose term)."""

HIP_ROLL_YAW_JOINTS = (
    "left_hip_roll_joint", "left_hip_yaw_joint", "right_hip_roll_joint", "right_hip_yaw_joint",
)  # fmt: skip
"""Hip joints that splay the legs when free (unitree_rl_gym's hip_pos term)."""

WALK_REWARDS = (
    RewardTerm("track_lin_vel_xy", walk_terms.track_lin_vel_xy_exp, weight=1.0),
    RewardTerm("track_ang_vel_z", walk_terms.track_ang_vel_z_exp, weight=0.5),
    RewardTerm("alive", rewards.alive, weight=0.5),
    # times dt 0.02 s: -2 per fall, so that falling never pays (tests/test_reward_recipes.py)
    RewardTerm("termination", rewards.termination, weight=-100.0),
    RewardTerm("gait_contact", walk_terms.gait_contact, weight=0.18),
    RewardTerm("feet_swing_height", walk_terms.feet_swing_height, weight=-20.0),
    RewardTerm("energy", walk_terms.energy_per_weight, weight=-0.1),
    RewardTerm("lin_vel_z", walk_terms.lin_vel_z_l2, weight=-2.0),
    RewardTerm("ang_vel_xy", rewards.base_ang_vel_xy_l2, weight=-0.05),
    RewardTerm("orientation", rewards.orientation_l2, weight=-1.0),
    RewardTerm("hip_pose", rewards.joint_deviation_named_l2, weight=-1.0,
               params={"joints": HIP_ROLL_YAW_JOINTS}),
    RewardTerm("upper_body_pose", rewards.joint_deviation_named_l2, weight=-0.5,
               params={"joints": UPPER_BODY_JOINTS}),
    RewardTerm("stand_still", walk_terms.stand_still, weight=-0.1),
    RewardTerm("feet_slide", rewards.feet_slide, weight=-0.2),
    RewardTerm("action_rate", rewards.action_rate_l2, weight=-0.01),
    RewardTerm("joint_acc", rewards.joint_acc_l2, weight=-2.5e-7),
    RewardTerm("joint_vel", rewards.joint_vel_l2, weight=-1e-3),
    RewardTerm("joint_pos_limits", rewards.joint_pos_limits, weight=-5.0),
)  # fmt: skip
"""The walk recipe that learns (unitree_rl_gym's G1 terms with a survival term, a gait clock, pose
terms and a mass-normalised energy term paid only under moving commands)."""

WALK_COMMANDS = VelocityCommandConfig(
    lin_vel_x_range_mps=(-0.5, 1.0),
    lin_vel_y_range_mps=(-0.3, 0.3),
    ang_vel_z_range_rps=(-1.0, 1.0),
    gait_period_s=0.8,
    curriculum_initial_scale=0.3,
)
"""Commands of the walk recipe: a 0.8 s gait clock and ranges that start at 30 % and widen while the
robots track within 0.25 m/s."""

_WALK_TERMINATIONS = (
    TerminationTerm(
        "base_contact", terminations.link_on_ground, params={"bodies": ("pelvis", "torso_link")}
    ),
    TerminationTerm("tilted", terminations.base_tilted, params={"max_tilt_rad": 1.0}),
)

WALK_FLAT = TaskConfig(
    name="walk-flat",
    description="follow velocity commands on flat ground (gait clock, command curriculum)",
    observations=STAND_OBSERVATIONS,
    rewards=WALK_REWARDS,
    terminations=_WALK_TERMINATIONS,
    assist_bound=paper_bound_rows("walk"),
    episode_length_s=20.0,
    pushes=PushConfig(interval_range_s=(5.0, 10.0), velocity_xy_mps=0.5),
    randomization=RandomizationConfig(),
    commands=WALK_COMMANDS,
    phases=SinglePhaseConfig(names=("walk",)),
    skill=SurvivalSkillConfig(target_survival=0.9),
    less_assist_weight=2.0,
    evaluation=WalkEvaluationConfig(),
    target=SkillTarget(min_survival=0.9, metric="lin_vel_error_mps", max_metric=0.25),
)
"""Walking on a plane: the target at CPU scale and the first stage of ``walk``."""

WALK = dataclasses.replace(
    WALK_FLAT,
    name="walk",
    description="follow velocity commands on rough terrain (10-level terrain curriculum)",
    observations=WALK_OBSERVATIONS,
    scene=SceneConfig(terrain=WALK_TERRAIN),
    # the swing-height term reads sole heights above z = 0, which only a plane makes right
    rewards=tuple(t for t in WALK_REWARDS if t.name != "feet_swing_height"),
    skill=TerrainCurriculumConfig(),
)
"""The walk task: the walk-flat recipe on the terrain curriculum (level 0 first)."""

WALK_PAPER = dataclasses.replace(
    WALK,
    name="walk-paper",
    description="the walk with the paper's reward table and command ranges (falling pays)",
    rewards=_WALK_PAPER_REWARDS,
    commands=VelocityCommandConfig(),
)
"""The walk with the paper's reward table term for term, and the old wide commands at once."""
