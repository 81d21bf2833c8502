"""``dance``: track dance clips (paper, "Dancing") with the clip-tracking command of
:mod:`rl.tasks.dance.command`.

Each episode starts on a frame drawn uniformly along one clip (drawn uniformly among the task's
clips: the built-in choreography by default, user CSV / NPZ clips with ``dance_task(clips)`` or
the run override ``TrainConfig(task_overrides={"commands.sources": [PATH, ...]})``), the robot put on that frame's pose and velocity and onto the
floor (retargeted clips hover or sink a few cm). Rewards are the paper's table: base displacement
``exp(-2500 |dp - dp_cmd|^2)`` 10, base step rotation ``exp(-100 |dq - dq_cmd|^2)`` 5, joints
``exp(-0.25 |q - q_cmd|^2)`` 20, feet slide -1, action rate -0.01, joint acceleration -2.5e-7,
torque -1e-5, less-assist 2. Skill learned: joint tracking error below 0.16 rad (mean absolute
error per joint). Flat ground, randomised friction, payload and CoM, no pushes. Initial assist
bound: the paper's dance row.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from rl.envs.assist import paper_bound_rows
from rl.envs.components import SinglePhaseConfig
from rl.envs.task_schema import InitialStateConfig, PushConfig, SkillTarget, TaskConfig
from rl.envs.terms import RewardTerm, TerminationTerm
from rl.tasks import rewards, terminations
from rl.tasks.dance.clips import BUILTIN_CLIP
from rl.tasks.dance.command import ClipTrackingConfig
from rl.tasks.dance.evaluation import DanceEvaluationConfig
from rl.tasks.dance.skill import TrackingSkillConfig
from rl.tasks.dance.terms import (
    track_base_position,
    track_base_rotation,
    track_joint_position,
    track_joint_rms,
)
from rl.tasks.stand.task import PROPRIOCEPTIVE_OBSERVATIONS


def dance_task(clips: tuple[str | Path, ...] = (BUILTIN_CLIP,)) -> TaskConfig:
    """The dance task tracking ``clips`` (``"builtin"`` and/or CSV / NPZ paths), one per episode."""
    sources = tuple(str(c) for c in clips)
    return dataclasses.replace(
        _DANCE,
        description=f"{_DANCE.description}; clips: {', '.join(sources)}",
        commands=dataclasses.replace(_DANCE.commands, sources=sources),
    )


_DANCE = TaskConfig(
    name="dance",
    description="track dance clips: command [base step displacement, step rotation, joints]",
    observations=PROPRIOCEPTIVE_OBSERVATIONS,
    rewards=(
        RewardTerm("base_position", track_base_position, weight=10.0, params={"scale": 2500.0}),
        RewardTerm("base_rotation", track_base_rotation, weight=5.0, params={"scale": 100.0}),
        # broad term: a gradient far from the reference (the paper's, at a quarter of its weight)
        RewardTerm("joint_position", track_joint_position, weight=5.0, params={"scale": 0.25}),
        # steep term around the 0.16 rad target (see docs/environments.md, "dance")
        RewardTerm("joint_rms", track_joint_rms, weight=15.0, params={"std_rad": 0.2}),
        RewardTerm("feet_slide", rewards.feet_slide, weight=-1.0),
        RewardTerm("action_rate", rewards.action_rate_l2, weight=-0.01),
        RewardTerm("joint_acc", rewards.joint_acc_l2, weight=-2.5e-7),
        RewardTerm("torques", rewards.torques_l2, weight=-1e-5),
        # times dt 0.02 s: -2 per fall (the paper's table pays 33/s for a fall in the first step,
        # more than holding a pose earns; tests/test_reward_recipes.py)
        RewardTerm("termination", rewards.termination, weight=-100.0),
    ),
    terminations=(
        TerminationTerm("too_low", terminations.base_too_low, params={"min_height_m": 0.4}),
        TerminationTerm("tilted", terminations.base_tilted, params={"max_tilt_rad": 1.0}),
        TerminationTerm(
            "link_on_ground",
            terminations.link_on_ground,
            params={"bodies": ("pelvis", "torso_link")},
        ),
    ),
    assist_bound=paper_bound_rows("dance"),
    episode_length_s=10.0,
    # The reset puts the robot exactly on its reference frame (the command's reset_state).
    initial_state=InitialStateConfig(joint_pos_noise_rad=0.0, base_vel_noise=0.0, random_yaw=False),
    pushes=PushConfig(enabled=False),
    commands=ClipTrackingConfig(),
    phases=SinglePhaseConfig(names=("dance",)),
    skill=TrackingSkillConfig(threshold_rad=0.16),
    less_assist_weight=2.0,
    evaluation=DanceEvaluationConfig(),
    target=SkillTarget(min_survival=0.0, metric="skill_error_rad", max_metric=0.16),
)

DANCE_JOINTS = dataclasses.replace(
    dance_task(),
    name="dance-joints",
    description="the earlier dance recipe: command [dp, dq, q], joint-tracking rewards (a standing "
    "robot beats its 0.16 rad target on the built-in dance; use track / dance)",
)
"""The earlier dance recipe (joint-error target, no statue), kept so its results reproduce."""

_PAPER_JOINT = RewardTerm(
    "joint_position", track_joint_position, weight=20.0, params={"scale": 0.25}
)
DANCE_PAPER = dataclasses.replace(
    DANCE_JOINTS,
    name="dance-paper",
    description="the dance with the paper's reward table term for term (joints exp(-0.25|e|^2) x 20)",
    rewards=tuple(
        _PAPER_JOINT if t.name == "joint_position" else t
        for t in DANCE_JOINTS.rewards
        if t.name not in ("joint_rms", "termination")
    ),
)
"""The dance with the paper's reward table (the reference the default recipe is compared with)."""
