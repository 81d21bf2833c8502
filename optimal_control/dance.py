"""A built-in G1 dance, generated with placo whole-body IK, so the dance pipeline runs offline.

The choreography (17.5 s) is a set of keyframed channels, each interpolated with
minimum-jerk (quintic smoothstep) segments:

* weight shifts: the CoM sways left and right over the double-support polygon (1.0-4.0 s),
* arm waves: each arm raised sideways, elbow waving (2.0-5.5 s),
* torso turns: waist yaw +-0.6 rad with the arms out (5.0-7.5 s),
* a squat: the CoM lowered by 0.15 m and raised again (7.5-9.5 s),
* a step: the CoM moves over the left sole, the right foot steps out 8 cm, the CoM moves to the
  middle of the wider stance and back over the left sole, the right foot steps back in
  (9.6-17.1 s); the right sole is out of contact while it swings.

The IK (placo ``KinematicsSolver`` at 200 Hz) holds each sole on its target (hard task), tracks
the CoM and keeps the pelvis level; the waist and arm joints follow joint targets. The soles stay
flat on the floor whenever they are in contact, and the CoM stays above the support polygon, but
the motion is kinematic: the oracle's QP says how much help its dynamics need.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from optimal_control.motion_clip import ClipConfig, reference_from_configurations
from optimal_control.reference import Reference
from optimal_control.validation import require_finite_fields, require_within
from optimal_control.walk import IK_DT_RANGE_S, _placo_robot
from robots import g1
from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model

DANCE_PHASES = ("dance",)


@dataclass(frozen=True)
class DanceConfig:
    """Sampling and amplitudes of the built-in dance."""

    output_fps: float = 50.0  # reference frame rate [1/s]
    ik_dt_s: float = 0.005  # whole-body IK step [s]
    sway_m: float = 0.06  # lateral CoM excursion of the weight shifts [m]
    squat_depth_m: float = 0.15  # CoM drop of the squat [m]
    turn_rad: float = 0.6  # waist yaw amplitude of the torso turns [rad]
    step_out_m: float = 0.08  # how far the right foot steps out sideways [m]
    step_height_m: float = 0.06  # swing-foot apex height [m]
    wave_hz: float = 1.5  # elbow wave frequency [1/s]
    smoothing_window_s: float = 0.1  # Savitzky-Golay window for v and a [s]

    def __post_init__(self) -> None:
        """Reject NaN / inf values and an IK step out of bounds, naming the field and its flag."""
        require_finite_fields(self)
        require_within(
            self, "ik_dt_s", *IK_DT_RANGE_S, "s",
            why="the IK runs the dance's length / ik_dt_s steps and follows the keyframes between "
            "them",
        )  # fmt: skip


def _smoothstep(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)


def keyframes(t: float, frames: list[tuple[float, float]]) -> float:
    """Value at time ``t`` of a channel given (time, value) keyframes, minimum-jerk in between."""
    if t <= frames[0][0]:
        return frames[0][1]
    for (t0, v0), (t1, v1) in zip(frames[:-1], frames[1:], strict=True):
        if t <= t1:
            return v0 + (v1 - v0) * float(_smoothstep(np.array((t - t0) / (t1 - t0))))
    return frames[-1][1]


@dataclass
class _Stance:
    com0: np.ndarray  # initial CoM [m]
    left0: np.ndarray  # initial left sole placement (4x4)
    right0: np.ndarray  # initial right sole placement (4x4)


SWING_WINDOWS_S = ((11.0, 11.8), (14.9, 15.7))
"""Times [s] during which the right sole is off the floor."""
DURATION_S = 17.5


def _targets(t: float, cfg: DanceConfig, st: _Stance) -> dict:
    left_y = st.left0[1, 3]
    right_y0 = st.right0[1, 3]
    right_y1 = right_y0 - cfg.step_out_m
    over_left = left_y - 0.005  # CoM above the left sole, 5 mm in from its centre line
    mid_wide = 0.5 * (left_y + right_y1)
    com_y = keyframes(
        t,
        [
            (1.0, 0.0),
            (1.75, cfg.sway_m),
            (2.75, -cfg.sway_m),
            (3.5, cfg.sway_m),
            (4.0, 0.0),
            (9.6, 0.0),
            (10.8, over_left),
            (12.0, over_left),
            (13.2, mid_wide),
            (13.5, mid_wide),
            (14.7, over_left),
            (15.9, over_left),
            (17.1, 0.0),
        ],
    )
    com_z = keyframes(
        t, [(7.5, 0.0), (8.3, -cfg.squat_depth_m), (8.6, -cfg.squat_depth_m), (9.4, 0.0)]
    )
    swing_up = cfg.step_height_m
    (a0, a1), (b0, b1) = SWING_WINDOWS_S
    right_y = keyframes(
        t,
        [
            (a0 + 0.05, right_y0),
            (a1 - 0.05, right_y1),
            (b0 + 0.05, right_y1),
            (b1 - 0.05, right_y0),
        ],
    )
    right_z = keyframes(
        t,
        [
            (a0, 0.0),
            (0.5 * (a0 + a1), swing_up),
            (a1, 0.0),
            (b0, 0.0),
            (0.5 * (b0 + b1), swing_up),
            (b1, 0.0),
        ],
    )
    wave_r = 0.5 * np.sin(2 * np.pi * cfg.wave_hz * (t - 2.5)) if 2.5 <= t <= 4.5 else 0.0
    wave_l = 0.5 * np.sin(2 * np.pi * cfg.wave_hz * (t - 3.0)) if 3.0 <= t <= 5.0 else 0.0
    fade_r = keyframes(t, [(2.3, 0.0), (2.5, 1.0), (4.5, 1.0), (4.7, 0.0)])
    fade_l = keyframes(t, [(2.8, 0.0), (3.0, 1.0), (5.0, 1.0), (5.2, 0.0)])
    joints = {
        "waist_yaw_joint": keyframes(
            t, [(5.0, 0.0), (5.7, cfg.turn_rad), (6.6, -cfg.turn_rad), (7.4, 0.0)]
        ),
        "right_shoulder_roll_joint": keyframes(
            t, [(2.0, -0.2), (2.5, -1.4), (4.6, -1.4), (5.2, -0.9), (7.3, -0.9), (7.6, -0.2)]
        ),
        "left_shoulder_roll_joint": keyframes(
            t, [(2.5, 0.2), (3.0, 1.4), (5.1, 1.4), (5.4, 0.9), (7.3, 0.9), (7.6, 0.2)]
        ),
        "right_elbow_joint": 0.6 + fade_r * (wave_r - 0.3),
        "left_elbow_joint": 0.6 + fade_l * (wave_l - 0.3),
        "right_shoulder_pitch_joint": keyframes(
            t, [(7.5, 0.2), (8.3, -0.8), (8.6, -0.8), (9.4, 0.2)]
        ),
        "left_shoulder_pitch_joint": keyframes(
            t, [(7.5, 0.2), (8.3, -0.8), (8.6, -0.8), (9.4, 0.2)]
        ),
    }
    right = st.right0.copy()
    right[1, 3] = right_y
    right[2, 3] = st.right0[2, 3] + right_z
    com = st.com0 + np.array([0.0, com_y, com_z])
    in_swing = any(a <= t < b for a, b in SWING_WINDOWS_S)
    return {"com": com, "right": right, "joints": joints, "right_contact": not in_swing}


@dataclass
class DancePlan:
    """The built-in dance reference and how long the IK took."""

    reference: Reference  # the 50 Hz whole-body reference (one phase "dance")
    ik_time_s: float  # whole-body IK over the dance [s]
    max_foot_error_m: float  # largest sole position error against its target [m]


def built_in_dance(cfg: DanceConfig = DanceConfig(), robot: G1Pinocchio | None = None) -> DancePlan:
    """Generate the built-in choreography (see the module docstring) as a reference."""
    import placo

    robot = robot or build_pinocchio_model()
    probot = _placo_robot()
    probot.state.q = robot.q_stand.copy()
    probot.update_kinematics()
    st = _Stance(
        com0=np.array(probot.com_world()),
        left0=np.array(probot.get_T_world_frame("left_foot")),
        right0=np.array(probot.get_T_world_frame("right_foot")),
    )
    solver = placo.KinematicsSolver(probot)
    solver.enable_velocity_limits(True)
    solver.dt = cfg.ik_dt_s
    left_task = solver.add_frame_task("left_foot", st.left0)
    left_task.configure("left_foot", "hard", 1.0, 1.0)
    right_task = solver.add_frame_task("right_foot", st.right0)
    right_task.configure("right_foot", "hard", 1.0, 1.0)
    com_task = solver.add_com_task(st.com0)
    com_task.configure("com", "soft", 100.0)
    trunk_task = solver.add_orientation_task("trunk", np.eye(3))
    trunk_task.configure("trunk", "soft", 1.0)
    joints_task = solver.add_joints_task()
    upper = [j.name for j in g1.JOINTS if j.name.split("_")[1] not in ("hip", "knee", "ankle")]
    joints_task.configure("upper_body", "soft", 1.0)
    solver.add_regularization_task(1e-4)

    t0 = time.perf_counter()
    num = int(round(DURATION_S / cfg.ik_dt_s)) + 1
    fine_q, contacts, foot_err = [], [], 0.0
    for k in range(num):
        t = k * cfg.ik_dt_s
        tg = _targets(t, cfg, st)
        com_task.target_world = tg["com"]
        right_task.T_world_frame = tg["right"]
        targets = {name: g1.STAND_JOINT_POS_RAD[g1.JOINT_NAMES.index(name)] for name in upper}
        targets.update(tg["joints"])
        joints_task.set_joints(targets)
        probot.update_kinematics()
        solver.solve(True)
        probot.update_kinematics()
        fine_q.append(probot.state.q.copy())
        contacts.append((True, tg["right_contact"]))
        for name, target in (("left_foot", st.left0), ("right_foot", tg["right"])):
            err = np.linalg.norm(probot.get_T_world_frame(name)[:3, 3] - target[:3, 3])
            foot_err = max(foot_err, float(err))
    ik_time = time.perf_counter() - t0
    fine_q = np.array(fine_q)
    stride = int(round(1.0 / (cfg.output_fps * cfg.ik_dt_s)))
    q = fine_q[::stride]
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    clip_cfg = ClipConfig(
        target_fps=cfg.output_fps,
        smoothing_window_s=cfg.smoothing_window_s,
        ground_to_lowest_sole=False,
    )
    ref = reference_from_configurations(
        q,
        1.0 / cfg.output_fps,
        clip_cfg,
        name="dance",
        phase_names=DANCE_PHASES,
        contacts=np.array(contacts, dtype=bool)[::stride],
        robot=robot,
    )
    return DancePlan(reference=ref, ik_time_s=ik_time, max_foot_error_m=foot_err)


def pose_summary(ref: Reference, robot: G1Pinocchio | None = None) -> dict:
    """Range of CoM height and waist yaw over a reference (a sanity check of the choreography)."""
    robot = robot or build_pinocchio_model()
    data = robot.data()
    com_z = [pin.centerOfMass(robot.model, data, q)[2] for q in ref.q]
    yaw = ref.q[:, robot.joint_q_index[g1.JOINT_NAMES.index("waist_yaw_joint")]]
    return {
        "com_z_range_m": [float(min(com_z)), float(max(com_z))],
        "waist_yaw_range_rad": [float(yaw.min()), float(yaw.max())],
    }
