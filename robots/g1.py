"""The Unitree G1 (29 DoF): the one table of joints, actuators, frames and poses.

Every other module (Pinocchio model, MuJoCo model, optimal control, RL) reads joint names, order,
gains, effort limits, armature, default poses and frame placements from here. Joint position and
velocity limits come from the URDF itself (read by the model builders), so nothing is copied.

Gains and effort limits follow the values commonly used for the G1 in mjlab / Unitree deployment
(dt 0.005 s, decimation 4). The ankle and waist roll/pitch joints are driven through a two-motor
linkage; their effort limit (50 Nm) is the pair's, higher than the single-motor 35 Nm the URDF lists.
Source of the 50 Nm: Unitree's own MuJoCo model of the G1 (unitree_mujoco / MuJoCo Menagerie
``unitree_g1/g1.xml``: ``ctrlrange="-50 50"`` on the ankle and waist roll/pitch motors) and mjlab's
G1 constants (two 5020 motors, 2 x 25 Nm). The simulators here use it; the backflip trajectory
optimisation uses the URDF's 35 Nm instead (conservative: a reference doable at 35 Nm is doable
at 50; ``optimal_control/backflip/sagittal.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ActuatorGroup:
    """PD gains and limits shared by the joints driven by one motor type."""

    name: str  # motor type label (Unitree naming)
    kp: float  # proportional gain [Nm/rad]
    kd: float  # derivative gain [Nm s/rad]
    effort_nm: float  # torque limit [Nm]
    armature: float  # reflected rotor inertia [kg m^2]


MOTOR_7520_14 = ActuatorGroup("7520-14", kp=40.18, kd=2.56, effort_nm=88.0, armature=0.0102)
MOTOR_7520_22 = ActuatorGroup("7520-22", kp=99.10, kd=6.31, effort_nm=139.0, armature=0.0251)
MOTOR_5020 = ActuatorGroup("5020", kp=14.25, kd=0.91, effort_nm=25.0, armature=0.0036)
MOTOR_5020_X2 = ActuatorGroup("2x5020", kp=28.50, kd=1.81, effort_nm=50.0, armature=0.0072)
MOTOR_4010 = ActuatorGroup("4010", kp=16.78, kd=1.07, effort_nm=5.0, armature=0.0043)


@dataclass(frozen=True)
class JointSpec:
    """One actuated joint of the G1."""

    name: str  # URDF joint name
    motor: ActuatorGroup  # gains and limits
    stand_rad: float = 0.0  # angle in the standing pose [rad]


# URDF depth-first order, which is also Pinocchio's and MuJoCo's order (tests check it).
JOINTS: tuple[JointSpec, ...] = (
    JointSpec("left_hip_pitch_joint", MOTOR_7520_14, -0.312),
    JointSpec("left_hip_roll_joint", MOTOR_7520_22),
    JointSpec("left_hip_yaw_joint", MOTOR_7520_14),
    JointSpec("left_knee_joint", MOTOR_7520_22, 0.669),
    JointSpec("left_ankle_pitch_joint", MOTOR_5020_X2, -0.363),
    JointSpec("left_ankle_roll_joint", MOTOR_5020_X2),
    JointSpec("right_hip_pitch_joint", MOTOR_7520_14, -0.312),
    JointSpec("right_hip_roll_joint", MOTOR_7520_22),
    JointSpec("right_hip_yaw_joint", MOTOR_7520_14),
    JointSpec("right_knee_joint", MOTOR_7520_22, 0.669),
    JointSpec("right_ankle_pitch_joint", MOTOR_5020_X2, -0.363),
    JointSpec("right_ankle_roll_joint", MOTOR_5020_X2),
    JointSpec("waist_yaw_joint", MOTOR_7520_14),
    JointSpec("waist_roll_joint", MOTOR_5020_X2),
    JointSpec("waist_pitch_joint", MOTOR_5020_X2),
    JointSpec("left_shoulder_pitch_joint", MOTOR_5020, 0.2),
    JointSpec("left_shoulder_roll_joint", MOTOR_5020, 0.2),
    JointSpec("left_shoulder_yaw_joint", MOTOR_5020),
    JointSpec("left_elbow_joint", MOTOR_5020, 0.6),
    JointSpec("left_wrist_roll_joint", MOTOR_5020),
    JointSpec("left_wrist_pitch_joint", MOTOR_4010),
    JointSpec("left_wrist_yaw_joint", MOTOR_4010),
    JointSpec("right_shoulder_pitch_joint", MOTOR_5020, 0.2),
    JointSpec("right_shoulder_roll_joint", MOTOR_5020, -0.2),
    JointSpec("right_shoulder_yaw_joint", MOTOR_5020),
    JointSpec("right_elbow_joint", MOTOR_5020, 0.6),
    JointSpec("right_wrist_roll_joint", MOTOR_5020),
    JointSpec("right_wrist_pitch_joint", MOTOR_4010),
    JointSpec("right_wrist_yaw_joint", MOTOR_4010),
)

NUM_JOINTS = len(JOINTS)
"""Number of actuated joints (29)."""

JOINT_NAMES: tuple[str, ...] = tuple(j.name for j in JOINTS)

BODY_PARTS: dict[str, slice] = {"legs": slice(0, 12), "waist": slice(12, 15), "arms": slice(15, 29)}
"""Joint index ranges of the body parts (:data:`JOINTS` order)."""

ACTION_SCALE_FACTOR = 0.25
"""Action a maps to a joint target default + scale * a with scale = 0.25 * effort / Kp."""


def _column(attr: str) -> np.ndarray:
    return np.array([getattr(j.motor, attr) for j in JOINTS], dtype=np.float64)


KP = _column("kp")
"""Proportional gains per joint [Nm/rad], shape (29,)."""
KD = _column("kd")
"""Derivative gains per joint [Nm s/rad], shape (29,)."""
EFFORT_LIMIT_NM = _column("effort_nm")
"""Torque limits per joint [Nm], shape (29,)."""
ARMATURE = _column("armature")
"""Reflected rotor inertia per joint [kg m^2], shape (29,)."""
STAND_JOINT_POS_RAD = np.array([j.stand_rad for j in JOINTS], dtype=np.float64)
"""Joint angles of the standing pose [rad], shape (29,)."""
ACTION_SCALE_RAD = ACTION_SCALE_FACTOR * EFFORT_LIMIT_NM / KP
"""Joint-target offset per unit action [rad], shape (29,)."""


@dataclass(frozen=True)
class FrameSpec:
    """An operational frame fixed to a URDF link, shared by Pinocchio (frame) and MuJoCo (site)."""

    name: str  # frame / site name
    link: str  # URDF link it is rigidly attached to
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # position in the link frame [m]


# Sole: the plane of the four URDF contact spheres (z = -0.03, radius 0.005) on the ankle-roll link,
# centred between heel (x = -0.05) and toe (x = 0.12).
SOLE_CENTER_OFFSET_M = (0.035, 0.0, -0.035)
SOLE_HALF_LENGTH_M = 0.085  # half extent along the foot x axis [m]
SOLE_HALF_WIDTH_M = 0.025  # half extent along the foot y axis, heel width (conservative) [m]

FRAMES: tuple[FrameSpec, ...] = (
    FrameSpec("pelvis", "pelvis"),
    FrameSpec("torso", "torso_link"),
    FrameSpec("imu_pelvis", "imu_in_pelvis"),
    FrameSpec("imu_torso", "imu_in_torso"),
    FrameSpec("left_sole", "left_ankle_roll_link", SOLE_CENTER_OFFSET_M),
    FrameSpec("right_sole", "right_ankle_roll_link", SOLE_CENTER_OFFSET_M),
    FrameSpec("left_hand", "left_rubber_hand"),
    FrameSpec("right_hand", "right_rubber_hand"),
)

SOLE_FRAMES = ("left_sole", "right_sole")
HAND_FRAMES = ("left_hand", "right_hand")
BASE_LINK = "pelvis"
"""The floating-base link; the assistive wrench acts on it."""


def sole_corners_m() -> np.ndarray:
    """Corners of a sole rectangle in the sole frame [m], shape (4, 3): heel-left, heel-right,
    toe-left, toe-right (z = 0 on the sole plane)."""
    lx, ly = SOLE_HALF_LENGTH_M, SOLE_HALF_WIDTH_M
    return np.array([[-lx, ly, 0.0], [-lx, -ly, 0.0], [lx, ly, 0.0], [lx, -ly, 0.0]])
