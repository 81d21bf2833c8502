"""A built-in G1 dance, generated with placo whole-body IK, so the dance pipeline runs offline.

The choreography (19 s, licence-free: written here) is a set of keyframed channels, each
interpolated with minimum-jerk (quintic smoothstep) segments, in six figures:

* settle (1-2 s): from standing into a bent-knee groove stance, the arms up and bent,
* sway (2-6 s): the CoM sways left and right with a bounce; the arm on the leaning side swings
  out, the other across the chest, the waist following,
* reach (6-8 s): both arms overhead, the wrists waving,
* twist (8-10 s): arms out sideways, waist yaw +-0.7 rad,
* squat (10-12 s): the CoM lowered by ``squat_depth_m``, the arms reaching forward,
* turn (12-17.2 s): four steps in place, each foot turned twice by ``turn_step_rad``, so the robot
  ends facing ``2 turn_step_rad`` (90 degrees) to its left, the arms swinging,
* home (17.2-19 s): back to the standing pose, held still for the last second.

The IK (placo ``KinematicsSolver`` at 200 Hz) holds each sole on its target (hard task), tracks
the CoM and keeps the pelvis level, turned with the feet; the waist and arm joints follow joint
targets. The soles stay flat on the floor whenever they are in contact, and the CoM stays above
the support polygon (over the support sole when a foot swings), but the motion is kinematic: the
oracle's QP says how much help its dynamics need.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from optimal_control.motion_clip import ClipConfig, reference_from_configurations
from optimal_control.reference import Reference
from optimal_control.validation import require_finite_fields, require_ranges, require_within
from optimal_control.walk import IK_DT_RANGE_S, _placo_robot
from robots import g1
from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model

DANCE_PHASES = ("dance",)


@dataclass(frozen=True)
class DanceConfig:
    """Sampling and amplitudes of the built-in dance."""

    output_fps: float = 50.0  # reference frame rate [1/s]
    ik_dt_s: float = 0.005  # whole-body IK step [s]
    groove_depth_m: float = 0.07  # CoM drop of the dance's bent-knee stance [m]
    sway_m: float = 0.06  # lateral CoM excursion of the sway [m]
    bounce_m: float = 0.03  # extra CoM drop at each end of the sway [m]
    squat_depth_m: float = 0.2  # CoM drop of the squat below standing [m]
    turn_rad: float = 0.7  # waist yaw amplitude of the twist [rad]
    turn_step_rad: float = 0.785  # how far each foot turns per step of the turn [rad]
    step_height_m: float = 0.06  # swing-foot apex height [m]
    wave_hz: float = 1.5  # wrist wave frequency overhead [1/s]
    smoothing_window_s: float = 0.1  # Savitzky-Golay window for v and a [s]

    def __post_init__(self) -> None:
        """Reject NaN / inf values and an IK step out of bounds, naming the field and its flag."""
        require_finite_fields(self)
        require_within(
            self, "ik_dt_s", *IK_DT_RANGE_S, "s",
            why="the IK runs the dance's length / ik_dt_s steps and follows the keyframes between "
            "them",
        )  # fmt: skip
        require_ranges(self, {
            "output_fps": (1.0, 1000.0, "1/s"), "groove_depth_m": (0.0, 1.0, "m"),
            "sway_m": (0.0, 1.0, "m"), "bounce_m": (0.0, 1.0, "m"),
            "squat_depth_m": (0.0, 1.0, "m"), "turn_rad": (0.0, 3.15, "rad"),
            "turn_step_rad": (0.0, 3.15, "rad"), "step_height_m": (0.0, 1.0, "m"),
            "wave_hz": (0.0, 20.0, "1/s"), "smoothing_window_s": (0.0, 5.0, "s"),
        })  # fmt: skip


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


DURATION_S = 19.0
TURN_START_S = 12.0
SHIFT_S = 0.55  # the CoM moves over the support sole before a foot lifts [s]
SWING_S = 0.75  # one swing of the turn [s]
TURN_FEET = ("left", "right", "left", "right")  # a left turn: the left foot opens first


def _turn_windows() -> tuple[tuple[str, float, float], ...]:
    """(foot, lift, land) [s] of the turn's steps."""
    windows, t = [], TURN_START_S
    for foot in TURN_FEET:
        windows.append((foot, t + SHIFT_S, t + SHIFT_S + SWING_S))
        t += SHIFT_S + SWING_S
    return tuple(windows)


SWING_WINDOWS_S = _turn_windows()
"""(foot, start, stop): times [s] during which that sole is off the floor."""
TURN_END_S = SWING_WINDOWS_S[-1][2]

# Arm poses, left arm (shoulder pitch, roll, yaw, elbow, wrist roll, pitch, yaw) [rad]; the right
# arm mirrors them (roll and yaws negated). Shoulder pitch < 0 raises the arm forward.
_ARM_STAND = (0.2, 0.2, 0.0, 0.6, 0.0, 0.0, 0.0)
_ARM_READY = (-0.6, 0.45, 0.0, 1.5, 0.3, 0.0, 0.3)  # forearms up, elbows bent
_ARM_OUT = (-0.4, 1.5, 0.6, 0.4, 0.9, 0.3, 0.0)  # swung out on the leaning side
_ARM_IN = (-1.2, 0.25, 0.4, 1.7, -0.6, 0.0, 0.5)  # hand in front of the chest
_ARM_UP = (-2.6, 0.35, 0.0, 0.6, 0.0, 0.5, 0.0)  # overhead
_ARM_T = (0.0, 1.55, 0.0, 0.2, 0.8, 0.0, 0.0)  # out sideways
_ARM_REACH = (-1.5, 0.15, 0.0, 0.2, 0.0, -0.6, 0.0)  # reaching forward
_ARM_FRONT = (-0.9, 0.4, 0.3, 1.3, 0.4, 0.0, 0.3)  # a walking swing, forward
_ARM_BACK = (0.6, 0.4, 0.0, 0.6, 0.4, 0.0, 0.3)  # and back
_ARM_JOINTS = ("shoulder_pitch", "shoulder_roll", "shoulder_yaw", "elbow", "wrist_roll",
               "wrist_pitch", "wrist_yaw")  # fmt: skip
_MIRRORED = {"shoulder_roll", "shoulder_yaw", "wrist_roll", "wrist_yaw"}


def _arm_keys(side: str) -> list[tuple[float, tuple[float, ...]]]:
    """Keyframes (time, pose) of one arm (poses as the left arm's, mirrored at use)."""
    lean_first = _ARM_OUT if side == "left" else _ARM_IN  # the sway goes left first
    lean_second = _ARM_IN if side == "left" else _ARM_OUT
    swing_first = _ARM_BACK if side == "left" else _ARM_FRONT  # opposite to the swinging foot
    swing_second = _ARM_FRONT if side == "left" else _ARM_BACK
    keys = [(1.0, _ARM_STAND), (2.0, _ARM_READY)]
    for k, t in enumerate((2.5, 3.5, 4.5, 5.5)):
        keys.append((t, lean_first if k % 2 == 0 else lean_second))
    keys += [(6.0, _ARM_READY), (6.6, _ARM_UP), (7.6, _ARM_UP), (8.2, _ARM_T), (9.8, _ARM_T)]
    keys += [(10.8, _ARM_REACH), (11.2, _ARM_REACH), (12.0, _ARM_READY)]
    for k, (_, lift, land) in enumerate(SWING_WINDOWS_S):
        keys.append((0.5 * (lift + land), swing_first if k % 2 == 0 else swing_second))
    keys += [(TURN_END_S + 0.4, _ARM_READY), (DURATION_S - 1.0, _ARM_STAND)]
    return keys


def _com_keys(cfg: DanceConfig) -> tuple[list, list]:
    """Lateral and vertical CoM keyframes [m] before the turn (body frame = world frame)."""
    sway, low = cfg.sway_m, -cfg.groove_depth_m
    y = [(2.0, 0.0)] + [(t, sway * (1 if k % 2 == 0 else -1)) for k, t in
                        enumerate((2.5, 3.5, 4.5, 5.5))] + [(6.0, 0.0)]  # fmt: skip
    z = [(1.0, 0.0), (2.0, low)]
    for t in (2.5, 3.5, 4.5, 5.5):
        z += [(t, low - cfg.bounce_m), (t + 0.5, low)]
    z += [(10.0, low), (10.8, -cfg.squat_depth_m), (11.2, -cfg.squat_depth_m), (12.0, low)]
    z += [(TURN_END_S + 0.4, low), (DURATION_S - 1.0, 0.0)]
    return y, z


def _rot_z(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class _Choreography:
    """Every channel's keyframes, from the standing pose's CoM and soles."""

    def __init__(self, cfg: DanceConfig, com0: np.ndarray, left0: np.ndarray, right0: np.ndarray):
        self.cfg, self.com0 = cfg, com0
        self.sole0 = {"left": left0, "right": right0}
        self.centre = 0.5 * (left0[:3, 3] + right0[:3, 3])
        self.centre[2] = 0.0
        self.com_y, self.com_z = _com_keys(cfg)
        self.yaw = {foot: [(0.0, 0.0)] for foot in self.sole0}
        for foot, lift, land in SWING_WINDOWS_S:
            turned = self.yaw[foot][-1][1] + cfg.turn_step_rad
            self.yaw[foot] += [(lift, self.yaw[foot][-1][1]), (land, turned)]
        self.com_xy = self._turn_com_keys()
        self.arms = {side: _arm_keys(side) for side in ("left", "right")}

    def sole(self, foot: str, t: float) -> np.ndarray:
        """Target placement (4, 4) of ``foot``'s sole at ``t``: turned about the stance centre."""
        yaw = keyframes(t, self.yaw[foot])
        pose = self.sole0[foot].copy()
        pose[:3, :3] = _rot_z(yaw) @ pose[:3, :3]
        pose[:3, 3] = self.centre + _rot_z(yaw) @ (pose[:3, 3] - self.centre)
        for f, lift, land in SWING_WINDOWS_S:
            if f == foot and lift <= t <= land:
                mid = 0.5 * (lift + land)
                apex = [(lift, 0.0), (mid, self.cfg.step_height_m), (land, 0.0)]
                pose[2, 3] += keyframes(t, apex)
        return pose

    def _turn_com_keys(self) -> list[tuple[float, np.ndarray]]:
        """CoM xy keyframes of the turn: over the support sole (1 cm inside) while a foot swings."""
        keys = [(TURN_START_S, self.com0[:2].copy())]
        for foot, lift, land in SWING_WINDOWS_S:
            support = "right" if foot == "left" else "left"
            sole = self.sole(support, lift)[:3, 3]
            inward = self.centre[:2] - sole[:2]
            over = sole[:2] + 0.01 * inward / np.linalg.norm(inward)
            offset = _rot_z(keyframes(lift, self.yaw[support]))[:2, :2] @ (
                self.com0[:2] - self.centre[:2]
            )
            keys += [(lift, over + offset), (land, over + offset)]
        keys.append((TURN_END_S + 0.6, self.com0[:2].copy()))
        return keys

    def targets(self, t: float) -> dict:
        """CoM, soles, pelvis yaw, joint targets and right/left contact at time ``t``."""
        com = self.com0.copy()
        if t >= TURN_START_S:
            com[:2] = _interp_vec(t, self.com_xy)
        com[1] += keyframes(t, self.com_y)
        com[2] += keyframes(t, self.com_z)
        soles = {foot: self.sole(foot, t) for foot in self.sole0}
        pelvis_yaw = 0.5 * sum(keyframes(t, self.yaw[foot]) for foot in self.sole0)
        joints = {}
        for side, keys in self.arms.items():
            pose = _interp_vec(t, [(tk, np.array(p)) for tk, p in keys])
            for name, value in zip(_ARM_JOINTS, pose, strict=True):
                sign = -1.0 if side == "right" and name in _MIRRORED else 1.0
                joints[f"{side}_{name}_joint"] = sign * float(value)
            if 6.6 <= t <= 7.6:  # the wrists wave overhead
                wave = 0.8 * np.sin(2 * np.pi * self.cfg.wave_hz * (t - 6.6))
                joints[f"{side}_wrist_roll_joint"] += float(wave) * (1 if side == "left" else -1)
        sway = keyframes(t, self.com_y) / max(self.cfg.sway_m, 1e-9)
        twist = keyframes(t, [(8.2, 0.0), (8.8, self.cfg.turn_rad), (9.4, -self.cfg.turn_rad),
                              (9.9, 0.0)])  # fmt: skip
        joints["waist_yaw_joint"] = 0.5 * sway + twist
        joints["waist_roll_joint"] = -0.25 * sway
        joints["waist_pitch_joint"] = keyframes(t, [(10.0, 0.0), (10.8, 0.3), (11.2, 0.3),
                                                     (12.0, 0.0)])  # fmt: skip
        contact = tuple(
            not any(f == foot and lift < t < land for f, lift, land in SWING_WINDOWS_S)
            for foot in ("left", "right")
        )
        return {"com": com, "soles": soles, "pelvis_yaw": pelvis_yaw, "joints": joints,
                "contacts": contact}  # fmt: skip


def _interp_vec(t: float, frames: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """:func:`keyframes` for vector values."""
    if t <= frames[0][0]:
        return np.asarray(frames[0][1], dtype=float)
    for (t0, v0), (t1, v1) in zip(frames[:-1], frames[1:], strict=True):
        if t <= t1:
            s = float(_smoothstep(np.array((t - t0) / (t1 - t0))))
            return np.asarray(v0, dtype=float) + (np.asarray(v1) - np.asarray(v0)) * s
    return np.asarray(frames[-1][1], dtype=float)


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
    sole0 = {foot: np.array(probot.get_T_world_frame(f"{foot}_foot")) for foot in ("left", "right")}
    dance = _Choreography(cfg, np.array(probot.com_world()), sole0["left"], sole0["right"])
    solver = placo.KinematicsSolver(probot)
    solver.enable_velocity_limits(True)
    solver.dt = cfg.ik_dt_s
    sole_tasks = {}
    for foot, pose in sole0.items():
        sole_tasks[foot] = solver.add_frame_task(f"{foot}_foot", pose)
        sole_tasks[foot].configure(f"{foot}_foot", "hard", 1.0, 1.0)
    com_task = solver.add_com_task(dance.com0)
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
        tg = dance.targets(k * cfg.ik_dt_s)
        com_task.target_world = tg["com"]
        for foot, task in sole_tasks.items():
            task.T_world_frame = tg["soles"][foot]
        trunk_task.R_world_frame = _rot_z(tg["pelvis_yaw"])
        targets = {name: g1.STAND_JOINT_POS_RAD[g1.JOINT_NAMES.index(name)] for name in upper}
        targets.update(tg["joints"])
        joints_task.set_joints(targets)
        probot.update_kinematics()
        solver.solve(True)
        probot.update_kinematics()
        fine_q.append(probot.state.q.copy())
        contacts.append(tg["contacts"])
        for foot, target in tg["soles"].items():
            err = np.linalg.norm(probot.get_T_world_frame(f"{foot}_foot")[:3, 3] - target[:3, 3])
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
    """Range of CoM height and waist yaw, and the mean |q - q_stand| of the joints (all, per body
    part) over a reference: how far from standing the choreography moves."""
    robot = robot or build_pinocchio_model()
    data = robot.data()
    com_z = [pin.centerOfMass(robot.model, data, q)[2] for q in ref.q]
    yaw = ref.q[:, robot.joint_q_index[g1.JOINT_NAMES.index("waist_yaw_joint")]]
    joints = ref.q[:, robot.joint_q_index] - g1.STAND_JOINT_POS_RAD
    return {
        "com_z_range_m": [float(min(com_z)), float(max(com_z))],
        "waist_yaw_range_rad": [float(yaw.min()), float(yaw.max())],
        "mean_abs_from_stand_rad": float(np.abs(joints).mean()),
        "mean_abs_from_stand_rad_by_part": {
            name: float(np.abs(joints[:, span]).mean()) for name, span in g1.BODY_PARTS.items()
        },
    }
