"""Former home of the walk's terms, kept so that ``rl.tasks.walk_terms`` imports keep working:
they now live in :mod:`rl.tasks.walk.terms`; import from there in new code."""

from rl.tasks.walk.terms import (
    cost_of_transport,
    energy_per_weight,
    feet_air_time,
    feet_swing_height,
    gait_contact,
    gait_phase,
    height_scan,
    lin_vel_z_l2,
    moving,
    scan_offsets_b,
    stand_still,
    track_ang_vel_z_exp,
    track_lin_vel_xy_exp,
)

__all__ = [
    "cost_of_transport",
    "energy_per_weight",
    "feet_air_time",
    "feet_swing_height",
    "gait_contact",
    "gait_phase",
    "height_scan",
    "lin_vel_z_l2",
    "moving",
    "scan_offsets_b",
    "stand_still",
    "track_ang_vel_z_exp",
    "track_lin_vel_xy_exp",
]
