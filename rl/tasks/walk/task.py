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

from rl.envs.assist import paper_bound_rows
from rl.envs.components import SinglePhaseConfig, SurvivalSkillConfig
from rl.envs.task_schema import (
    ObservationsConfig,
    PushConfig,
    RandomizationConfig,
    SceneConfig,
    SkillTarget,
    TaskConfig,
)
from rl.envs.terms import ObsGroup, ObsTerm, RewardTerm, TerminationTerm
from rl.tasks import rewards, terminations
from rl.tasks.stand.task import (
    CRITIC_EXTRA,
    PRIVILEGED,
    PROPRIOCEPTION,
    PROPRIOCEPTIVE_OBSERVATIONS,
)
from rl.tasks.walk import terms as walk_terms
from rl.tasks.walk.command import VelocityCommandConfig
from rl.tasks.walk.curriculum import WALK_TERRAIN, TerrainCurriculumConfig
from rl.tasks.walk.evaluation import WalkEvaluationConfig
from robots import g1

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

WALK_FLAT_OBSERVATIONS = PROPRIOCEPTIVE_OBSERVATIONS
"""What the G1 senses (IMU, joint encoders, last action, command and gait clock): the motion head
reads the history encoder's velocity estimate beside it, and the true pelvis velocity stays
privileged (assist head, critic), as in the paper."""

WALK_FLAT_TRACKING_WEIGHTS = {"track_lin_vel_xy": 2.0, "track_ang_vel_z": 2.0}
"""mjlab's linear tracking weight (standing under a moving command forgoes 4x the 0.5 survival
pay), and the yaw-rate term weighed as much, so that turning pays (``docs/environments.md``)."""

WALK_FLAT_REWARDS = tuple(
    dataclasses.replace(t, weight=WALK_FLAT_TRACKING_WEIGHTS[t.name])
    if t.name in WALK_FLAT_TRACKING_WEIGHTS
    else t
    for t in WALK_REWARDS
)
"""The walk recipe with the tracking weights of :data:`WALK_FLAT_TRACKING_WEIGHTS`."""

WALK_FLAT_COMMANDS = dataclasses.replace(
    WALK_COMMANDS, curriculum_initial_scale=1.0, pure_fraction=0.4
)
"""The walk commands at their full ranges from the start (mjlab's G1 velocity), and 40 % of the
moving draws pure (forward or backward, sideways, or turning on the spot), the kinds the judge
holds alone (``docs/environments.md``)."""

_WALK_TERMINATIONS = (
    TerminationTerm(
        "base_contact", terminations.link_on_ground, params={"bodies": ("pelvis", "torso_link")}
    ),
    TerminationTerm("tilted", terminations.base_tilted, params={"max_tilt_rad": 1.0}),
)

WALK_FLAT = TaskConfig(
    name="walk-flat",
    description="follow velocity commands on flat ground (gait clock, velocity observed)",
    observations=WALK_FLAT_OBSERVATIONS,
    rewards=WALK_FLAT_REWARDS,
    terminations=_WALK_TERMINATIONS,
    assist_bound=paper_bound_rows("walk"),
    episode_length_s=20.0,
    pushes=PushConfig(interval_range_s=(5.0, 10.0), velocity_xy_mps=0.5),
    randomization=RandomizationConfig(),
    commands=WALK_FLAT_COMMANDS,
    phases=SinglePhaseConfig(names=("walk",)),
    skill=SurvivalSkillConfig(target_survival=0.9),
    less_assist_weight=2.0,
    # 5 PPO passes x 4 mini-batches over 128 x 24 samples: the late mini-batches overshot the KL
    # target and held the adaptive rate at its floor (docs/environments.md)
    learning_epochs=2,
    vae_learning_epochs=1,
    oracle_tasks=("walk",),  # solve-walk's gait is on flat ground
    evaluation=WalkEvaluationConfig(judge_kinds=True),
    # every command kind within half of a robot standing still's error (walk/evaluation.py)
    target=SkillTarget(min_survival=0.9, metric="command_score", max_metric=1.0),
)
"""Walking on a plane: the target at CPU scale and the first stage of ``walk``."""

WALK = dataclasses.replace(
    WALK_FLAT,
    name="walk",
    description="follow velocity commands on rough terrain (10-level terrain curriculum)",
    observations=WALK_OBSERVATIONS,
    commands=WALK_COMMANDS,
    scene=SceneConfig(terrain=WALK_TERRAIN),
    # the swing-height term reads sole heights above z = 0, which only a plane makes right
    rewards=tuple(t for t in WALK_REWARDS if t.name != "feet_swing_height"),
    skill=TerrainCurriculumConfig(),
)
"""The walk task: the walk-flat v1 recipe (no velocity observed, tracking weight 1.0, the command
curriculum from 30 %) with walk-flat's 2 + 1 update passes, on the terrain curriculum (level 0
first)."""

WALK_PAPER = dataclasses.replace(
    WALK,
    name="walk-paper",
    description="the walk with the paper's reward table and command ranges (falling pays)",
    rewards=_WALK_PAPER_REWARDS,
    commands=VelocityCommandConfig(),
    learning_epochs=5,  # the paper's update (rsl-rl's defaults), for its 4096-env batches
    vae_learning_epochs=0,
)
"""The walk with the paper's reward table term for term, and the old wide commands at once."""
