"""Former home of the dance's terms, kept so that ``rl.tasks.dance_terms`` imports keep working:
everything now lives in the :mod:`rl.tasks.dance` package (terms, clips, command, skill,
evaluation); import from there in new code."""

from rl.envs.state import yaw_rad as yaw_of
from rl.tasks.dance.clips import (
    BUILTIN_CLIP,
    ClipLibrary,
    clip_library,
    frame_commands,
    load_reference,
)
from rl.tasks.dance.command import ClipTrackingCommand, ClipTrackingConfig
from rl.tasks.dance.evaluation import quat_angle
from rl.tasks.dance.skill import TrackingSkill, TrackingSkillConfig
from rl.tasks.dance.terms import (
    COMMAND_DIM,
    base_displacement_error_sq,
    base_rotation_error_sq,
    joint_error_mean_abs,
    joint_error_sq,
    split_command,
    step_displacement,
    step_rotation,
    track_base_position,
    track_base_rotation,
    track_joint_position,
    track_joint_rms,
)
from robots.g1 import BODY_PARTS

__all__ = [
    "BODY_PARTS",
    "BUILTIN_CLIP",
    "COMMAND_DIM",
    "ClipLibrary",
    "ClipTrackingCommand",
    "ClipTrackingConfig",
    "TrackingSkill",
    "TrackingSkillConfig",
    "base_displacement_error_sq",
    "base_rotation_error_sq",
    "clip_library",
    "frame_commands",
    "joint_error_mean_abs",
    "joint_error_sq",
    "load_reference",
    "quat_angle",
    "split_command",
    "step_displacement",
    "step_rotation",
    "track_base_position",
    "track_base_rotation",
    "track_joint_position",
    "track_joint_rms",
    "yaw_of",
]
