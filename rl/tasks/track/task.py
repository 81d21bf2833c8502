"""``track``: track any reference motion (a dance clip, an oracle artifact's motion) with the
whole-body tracking recipe of :mod:`rl.tasks.track.terms`; ``dance`` is ``track`` on the built-in
choreography.

Actions: joint PD targets around the reference frame's joints (``q_ref + scale a``; DReCon's
residual targets; whole_body_tracking's are around the standing pose). Rewards
(whole_body_tracking's G1 recipe, weights per second): anchor position 0.5 (std 0.3 m)
and orientation 0.5 (0.4 rad), body positions 1.0 (0.3 m) and orientations 1.0 (0.4 rad) relative
to the anchor, body linear 1.0 (1 m/s) and angular velocities 1.0 (3.14 rad/s); action rate -0.1,
joint limits -10, link contacts (all but the feet) -0.1; less-assist 2 (A2CF).
``--task-action-feedforward`` adds the reference's joint rates and an oracle artifact's planned
joint torques to the PD law (zero action is then the oracle's own control). Episodes start on
the reference (reference state initialisation, adaptive start sampling) and end at its last frame
(a time-out), at the 20 s cap, or on a drift termination. Flat ground, randomised friction,
payload and CoM, no pushes. Skill: :mod:`rl.tasks.track.evaluation` (a statue fails it).
"""

from __future__ import annotations

import dataclasses

from rl.envs.assist import paper_bound_rows
from rl.envs.components import SinglePhaseConfig
from rl.envs.task_schema import InitialStateConfig, PushConfig, SceneConfig, SkillTarget, TaskConfig
from rl.envs.terms import RewardTerm, TerminationTerm
from rl.tasks import rewards
from rl.tasks.dance.clips import BUILTIN_CLIP
from rl.tasks.stand.task import PROPRIOCEPTIVE_OBSERVATIONS
from rl.tasks.track import terms
from rl.tasks.track.command import MotionCommandConfig
from rl.tasks.track.evaluation import TrackEvaluationConfig
from rl.tasks.track.skill import MotionSkillConfig

TRACK = TaskConfig(
    name="track",
    description="track a reference motion (--reference PATH...; default: the built-in dance): "
    "command [q_ref, qd_ref, anchor pose seen from the robot]",
    observations=PROPRIOCEPTIVE_OBSERVATIONS,
    rewards=(
        RewardTerm("anchor_position", terms.anchor_position, weight=0.5, params={"std": 0.3}),
        RewardTerm("anchor_orientation", terms.anchor_orientation, weight=0.5, params={"std": 0.4}),
        RewardTerm("body_position", terms.body_position, weight=1.0, params={"std": 0.3}),
        RewardTerm("body_orientation", terms.body_orientation, weight=1.0, params={"std": 0.4}),
        RewardTerm("body_lin_vel", terms.body_linear_velocity, weight=1.0, params={"std": 1.0}),
        RewardTerm("body_ang_vel", terms.body_angular_velocity, weight=1.0, params={"std": 3.14}),
        # Off in whole_body_tracking's recipe; --task-reward-weight joint_position=W turns it on.
        RewardTerm("joint_position", terms.joint_position, weight=0.0, params={"std": 0.2}),
        RewardTerm("action_rate", rewards.action_rate_l2, weight=-0.1),
        RewardTerm("joint_limits", rewards.joint_pos_limits, weight=-10.0),
        RewardTerm("link_contacts", rewards.link_ground_contact, weight=-0.1),
    ),
    terminations=(
        TerminationTerm("anchor_height", terms.anchor_height_drift, params={"max_m": 0.25}),
        TerminationTerm(
            "anchor_tilt", terms.anchor_tilt_drift, params={"max_rad": 0.8, "free_phases": ()}
        ),
        TerminationTerm(
            "end_effector_height",
            terms.end_effector_height_drift,
            params={"max_m": 0.25, "free_phases": ()},
        ),
    ),
    assist_bound=paper_bound_rows("dance"),
    episode_length_s=20.0,
    scene=SceneConfig(tracked_bodies=terms.TRACKED_BODIES),
    # The reset puts the robot exactly on its reference frame (the command's reset_state).
    initial_state=InitialStateConfig(joint_pos_noise_rad=0.0, base_vel_noise=0.0, random_yaw=False),
    pushes=PushConfig(enabled=False),
    commands=MotionCommandConfig(),
    phases=SinglePhaseConfig(names=("track",)),
    skill=MotionSkillConfig(threshold_rad=0.16),
    less_assist_weight=2.0,
    # PD targets around the reference's joints (q_ref + scale a), not the standing pose: around
    # the standing pose the joints stayed at a statue's error (docs/results/track_learn);
    # --no-task-actions-around-reference
    actions_around_reference=True,
    evaluation=TrackEvaluationConfig(),
    target=SkillTarget(min_survival=0.9, metric="tracking_score", max_metric=1.0),
    learning_epochs=2,
    vae_learning_epochs=1,
)
"""The registered tracking task (default reference: the built-in dance)."""


def track_task(
    references: tuple[str, ...] = (BUILTIN_CLIP,), frames: str = "", name: str = "track"
) -> TaskConfig:
    """The tracking task on ``references`` (segment ``frames`` "A:B" of each), named ``name``."""
    sources = tuple(str(r) for r in references)
    return dataclasses.replace(
        TRACK,
        name=name,
        description=f"{TRACK.description}; references: {', '.join(sources)}",
        commands=dataclasses.replace(TRACK.commands, sources=sources, frames=frames),
    )


def adapt_to_references(task: TaskConfig) -> TaskConfig:
    """A tracking ``task`` set up for the references it tracks: their phases where they share
    more than one (an oracle artifact's, or the time bins of the artifact ``train --oracle``
    solved; the bound row repeated per phase), and the flip setup
    (:func:`rl.tasks.track.flip.for_flips`) where every reference turns over."""
    import math

    from optimal_control.reference_sources import parse_frames
    from rl.tasks.track.flip import for_flips
    from rl.tasks.track.library import load_track_reference, pitch_turn_rad, reference_phase_names
    from rl.tasks.track.phases import ReferencePhaseConfig

    cmd = task.commands
    refs = [
        load_track_reference(
            s, parse_frames(cmd.frames), cmd.step_dt_s, cmd.oracle, cmd.oracle_phases
        )
        for s in cmd.sources
    ]
    names = reference_phase_names(refs)
    if len(names) > 1 and isinstance(task.phases, SinglePhaseConfig):
        row = tuple(max(col) for col in zip(*task.assist_bound, strict=True))
        task = dataclasses.replace(
            task, phases=ReferencePhaseConfig(names=names), assist_bound=(row,) * len(names)
        )
    turns = [pitch_turn_rad(r.q[:, [6, 3, 4, 5]]) for r in refs]  # Pinocchio x y z w -> w x y z
    if all(abs(t) > math.pi for t in turns):
        task = for_flips(task, refs, turns[0])
    return with_drift_free_phases(task)


DRIFT_TERMINATIONS = ("anchor_tilt", "end_effector_height")
"""The tracking terminations that ``TaskConfig.drift_free_phases`` switches off by phase."""


def with_drift_free_phases(task: TaskConfig) -> TaskConfig:
    """``task`` with its drift terminations off in ``task.drift_free_phases`` (their phase
    indices as the terms' ``free_phases``); unchanged when it names none. An unknown phase is
    refused with the task's phases."""
    if not task.drift_free_phases:
        return task
    names = task.phase_names
    unknown = [p for p in task.drift_free_phases if p not in names]
    if unknown:
        raise ValueError(
            f"--task-drift-free-phases {' '.join(unknown)}: task '{task.name}' has no such "
            f"phase; its phases: {' '.join(names)} (a solve-backflip artifact's reference gives "
            "stand crouch jump air land)"
        )
    free = tuple(names.index(p) for p in task.drift_free_phases)
    return task.with_term_params({t: {"free_phases": free} for t in DRIFT_TERMINATIONS})


DANCE = dataclasses.replace(
    TRACK,
    name="dance",
    description="track the built-in dance (the track task on it; --reference for clips)",
    phases=SinglePhaseConfig(names=("dance",)),
)
"""The dance: ``track`` on the built-in choreography (phase named "dance", as its oracle's)."""
