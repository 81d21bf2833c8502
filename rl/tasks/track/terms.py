"""The tracking task's bodies, command layout, reward and termination terms.

The recipe is the public state of the art for whole-body motion tracking (whole_body_tracking /
BeyondMimic, mjlab's tracking task), written here over :class:`rl.envs.state.EnvState`: the
robot's tracked links (``EnvState.body_*``) against the reference's (``EnvState.targets``, the
frame the robot should reach with this step, from :class:`rl.tasks.track.command.MotionCommand`).
Every tracking reward is ``exp(-err^2 / std^2)``:

* anchor (torso) position and orientation in the world;
* body positions and orientations *relative to the anchor*: the reference's bodies are moved so
  that its anchor sits over the robot's (the robot's x y, the reference's height) and turned by
  the heading difference, so a robot that drifted or turned a little is judged by its posture;
* body linear and angular velocities in the world.

Terminations: the anchor's height off by more than 0.25 m, its up axis off by more than 0.8 rad,
or an end effector's (ankles, wrists) height off by more than 0.25 m.
"""

from __future__ import annotations

import torch

from rl.envs.state import EnvState, quat_multiply, quat_rotate, quat_rotate_inverse, yaw_rad
from robots import g1

TRACKED_BODIES = (
    "pelvis",
    "left_hip_roll_link", "left_knee_link", "left_ankle_roll_link",
    "right_hip_roll_link", "right_knee_link", "right_ankle_roll_link",
    "torso_link",
    "left_shoulder_roll_link", "left_elbow_link", "left_wrist_yaw_link",
    "right_shoulder_roll_link", "right_elbow_link", "right_wrist_yaw_link",
)  # fmt: skip
"""The links whose poses are tracked (whole_body_tracking's G1 set), K = 14."""
ANCHOR_BODY = "torso_link"
"""The link the other bodies are judged relative to."""
ANCHOR = TRACKED_BODIES.index(ANCHOR_BODY)
END_EFFECTORS = tuple(
    TRACKED_BODIES.index(b)
    for b in ("left_ankle_roll_link", "right_ankle_roll_link", "left_wrist_yaw_link",
              "right_wrist_yaw_link")
)  # fmt: skip
"""Indices (into :data:`TRACKED_BODIES`) of the links whose height drift ends an episode."""

COMMAND_DIM = 2 * g1.NUM_JOINTS + 3 + 6
"""Command width: reference joints (29) and joint rates (29), the reference anchor's position in
the robot anchor's frame (3) and its orientation there (first two rotation-matrix columns, 6)."""


# ---------------------------------------------------------------------------- quaternion helpers
def quat_conjugate(q_wxyz: torch.Tensor) -> torch.Tensor:
    """Conjugate (inverse of a unit quaternion) of (..., 4) w x y z."""
    return q_wxyz * torch.tensor([1.0, -1.0, -1.0, -1.0], device=q_wxyz.device)


def quat_angle(a_wxyz: torch.Tensor, b_wxyz: torch.Tensor) -> torch.Tensor:
    """Rotation angle between orientations (..., 4) w x y z [rad], in [0, pi]."""
    shape = a_wxyz.shape[:-1]
    rel = quat_multiply(quat_conjugate(b_wxyz).reshape(-1, 4), a_wxyz.reshape(-1, 4))
    angle = 2 * torch.atan2(rel[:, 1:].norm(dim=-1), rel[:, 0].abs())
    return angle.reshape(shape)


def yaw_quat(yaw: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (N, 4) w x y z of rotations by ``yaw`` (N,) [rad] about world z."""
    zero = torch.zeros_like(yaw)
    return torch.stack([torch.cos(yaw / 2), zero, zero, torch.sin(yaw / 2)], dim=-1)


def rotation_6d(q_wxyz: torch.Tensor) -> torch.Tensor:
    """First two columns of the rotation matrices of (N, 4) w x y z, flattened (N, 6)."""
    ex = torch.tensor([1.0, 0.0, 0.0], device=q_wxyz.device).expand(q_wxyz.shape[0], 3)
    ey = torch.tensor([0.0, 1.0, 0.0], device=q_wxyz.device).expand(q_wxyz.shape[0], 3)
    return torch.cat([quat_rotate(q_wxyz, ex), quat_rotate(q_wxyz, ey)], dim=-1)


def _per_body(fn, quat: torch.Tensor, vec: torch.Tensor) -> torch.Tensor:
    """``fn(quat, vec)`` over (N, 4) quaternions and (N, K, 3) vectors, (N, K, 3)."""
    n, k = vec.shape[:2]
    return fn(quat.unsqueeze(1).expand(n, k, 4).reshape(-1, 4), vec.reshape(-1, 3)).reshape(n, k, 3)


# ----------------------------------------------------------------------- the reference, re-anchored
def relative_reference_bodies(s: EnvState) -> tuple[torch.Tensor, torch.Tensor]:
    """The reference's body positions (N, K, 3) [m] and orientations (N, K, 4) moved so that its
    anchor is over the robot's anchor (robot x y, reference z) and turned by their heading
    difference (whole_body_tracking's relative body pose)."""
    ref_pos, ref_quat = s.targets["body_pos_w"], s.targets["body_quat_w"]
    ref_anchor_pos, ref_anchor_quat = ref_pos[:, ANCHOR], ref_quat[:, ANCHOR]
    anchor_pos, anchor_quat = s.body_pos_w[:, ANCHOR], s.body_quat_w[:, ANCHOR]
    delta_yaw = yaw_quat(yaw_rad(anchor_quat) - yaw_rad(ref_anchor_quat))
    origin = torch.cat([anchor_pos[:, :2], ref_anchor_pos[:, 2:]], dim=-1)
    pos = origin.unsqueeze(1) + _per_body(quat_rotate, delta_yaw, ref_pos - ref_anchor_pos[:, None])
    n, k = ref_quat.shape[:2]
    quat = quat_multiply(
        delta_yaw.unsqueeze(1).expand(n, k, 4).reshape(-1, 4), ref_quat.reshape(-1, 4)
    )
    return pos, quat.reshape(n, k, 4)


def anchor_command(
    anchor_pos_w: torch.Tensor,
    anchor_quat_w: torch.Tensor,
    ref_anchor_pos_w: torch.Tensor,
    ref_anchor_quat_w: torch.Tensor,
) -> torch.Tensor:
    """Where the reference anchor is, seen from the robot's anchor: its position in the robot
    anchor's frame (N, 3) [m] and its relative orientation as two rotation columns (N, 6)."""
    pos_b = quat_rotate_inverse(anchor_quat_w, ref_anchor_pos_w - anchor_pos_w)
    rel = quat_multiply(quat_conjugate(anchor_quat_w), ref_anchor_quat_w)
    return torch.cat([pos_b, rotation_6d(rel)], dim=-1)


# ------------------------------------------------------------------------------------ rewards
def _exp(err_sq: torch.Tensor, std: float) -> torch.Tensor:
    return torch.exp(-err_sq / std**2)


def anchor_position(s: EnvState, std: float = 0.3) -> torch.Tensor:
    """``exp(-|p_anchor - p_anchor_ref|^2 / std^2)`` (N,) [-] (``std`` [m])."""
    err = s.body_pos_w[:, ANCHOR] - s.targets["body_pos_w"][:, ANCHOR]
    return _exp(err.square().sum(-1), std)


def anchor_orientation(s: EnvState, std: float = 0.4) -> torch.Tensor:
    """``exp(-angle(q_anchor, q_anchor_ref)^2 / std^2)`` (N,) [-] (``std`` [rad])."""
    angle = quat_angle(s.body_quat_w[:, ANCHOR], s.targets["body_quat_w"][:, ANCHOR])
    return _exp(angle.square(), std)


def body_position(s: EnvState, std: float = 0.3) -> torch.Tensor:
    """``exp(-mean_k |p_k - p_k_ref,rel|^2 / std^2)`` over the tracked bodies (N,) [-] [m]."""
    pos, _ = relative_reference_bodies(s)
    return _exp((s.body_pos_w - pos).square().sum(-1).mean(-1), std)


def body_orientation(s: EnvState, std: float = 0.4) -> torch.Tensor:
    """``exp(-mean_k angle(q_k, q_k_ref,rel)^2 / std^2)`` (N,) [-] [rad]."""
    _, quat = relative_reference_bodies(s)
    return _exp(quat_angle(s.body_quat_w, quat).square().mean(-1), std)


def body_linear_velocity(s: EnvState, std: float = 1.0) -> torch.Tensor:
    """``exp(-mean_k |v_k - v_k_ref|^2 / std^2)``, world frame (N,) [-] [m/s]."""
    err = s.body_lin_vel_w - s.targets["body_lin_vel_w"]
    return _exp(err.square().sum(-1).mean(-1), std)


def body_angular_velocity(s: EnvState, std: float = 3.14) -> torch.Tensor:
    """``exp(-mean_k |w_k - w_k_ref|^2 / std^2)``, world frame (N,) [-] [rad/s]."""
    err = s.body_ang_vel_w - s.targets["body_ang_vel_w"]
    return _exp(err.square().sum(-1).mean(-1), std)


def joint_position(s: EnvState, std: float = 0.2) -> torch.Tensor:
    """``exp(-mean_j (q_j - q_j_ref)^2 / std^2)`` over the 29 joints (N,) [-] (``std`` [rad]): steep
    where the body kernels are flat (with std 0.2 it pays 0.61 at an RMS error of 0.14 rad, 0.04 at
    0.36, about a statue's on a dance)."""
    return _exp((s.joint_pos_rad - s.targets["joint_pos_rad"]).square().mean(-1), std)


def joint_error_mean_abs(s: EnvState) -> torch.Tensor:
    """Mean absolute joint tracking error over the 29 joints (N,) [rad]."""
    return (s.joint_pos_rad - s.targets["joint_pos_rad"]).abs().mean(-1)


# ------------------------------------------------------------------------------- terminations
def anchor_height_drift(s: EnvState, max_m: float = 0.25) -> torch.Tensor:
    """The anchor's height is more than ``max_m`` [m] off the reference's (N,) bool."""
    return (s.body_pos_w[:, ANCHOR, 2] - s.targets["body_pos_w"][:, ANCHOR, 2]).abs() > max_m


def _outside(s: EnvState, phases: tuple[int, ...]) -> torch.Tensor | bool:
    """(N,) bool: the env's phase is none of ``phases`` (True for all when there are none)."""
    if not phases:
        return True
    return ~torch.isin(s.phase, torch.as_tensor(phases, device=s.phase.device))


def anchor_tilt_drift(
    s: EnvState, max_rad: float = 0.8, free_phases: tuple[int, ...] = ()
) -> torch.Tensor:
    """The anchor's up axis is more than ``max_rad`` [rad] off the reference's (N,) bool (the
    heading is free: a turned robot that tracks its posture has not failed); never in
    ``free_phases`` (phase indices: a flip's flight, ``TaskConfig.drift_free_phases``)."""
    up = torch.tensor([0.0, 0.0, 1.0], device=s.body_quat_w.device).expand(
        s.body_quat_w.shape[0], 3
    )
    a = quat_rotate(s.body_quat_w[:, ANCHOR], up)
    b = quat_rotate(s.targets["body_quat_w"][:, ANCHOR], up)
    return (torch.acos((a * b).sum(-1).clamp(-1.0, 1.0)) > max_rad) & _outside(s, free_phases)


def end_effector_height_drift(
    s: EnvState, max_m: float = 0.25, free_phases: tuple[int, ...] = ()
) -> torch.Tensor:
    """An end effector's (ankles, wrists) height is more than ``max_m`` [m] off (N,) bool; never
    in ``free_phases`` (phase indices)."""
    idx = list(END_EFFECTORS)
    err = (s.body_pos_w[:, idx, 2] - s.targets["body_pos_w"][:, idx, 2]).abs()
    return (err > max_m).any(-1) & _outside(s, free_phases)
