"""G1 whole-body walking references from placo's walk pattern generator.

placo plans footsteps for a commanded velocity (vx, vy, wz), a CoM trajectory (LIPM with ZMP
constraints in the sole polygons, kept in the reference as ``extras["com_plan_w"]`` (T, 3)) and
swing-foot trajectories; its whole-body kinematics solver
(feet, CoM and trunk-orientation tasks, upper body held at the standing pose by a joint task) turns
them into joint trajectories. The IK runs at ``ik_dt_s`` (200 Hz), the reference is kept at
``output_fps`` (50 Hz); velocities and accelerations come from
:func:`optimal_control.motion_clip.differentiate` on the fine IK samples.

placo's ``HumanoidRobot`` expects frames ``left_foot``, ``right_foot`` and ``trunk``; the G1 URDF
has none, so :func:`placo_urdf_text` adds them as fixed links (soles on the ankle-roll links at
:data:`robots.g1.SOLE_CENTER_OFFSET_M`, trunk on the pelvis, not the torso, or the pelvis tilts).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from optimal_control.motion_clip import differentiate
from optimal_control.reference import Reference
from optimal_control.validation import require_finite_fields, require_ranges, require_within
from robots import g1
from robots.assets import g1_urdf_path
from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model

WALK_PHASES = ("double_support", "single_support")

MAX_WALK_DURATION_S = 120.0
"""Longest walk reference: a walk repeats one step cycle, so eta0 (a percentile per phase) learns
nothing from a longer one, while placo's plan, the IK and the per-frame QPs grow with it [s]."""
IK_DT_RANGE_S = (0.001, 0.02)
"""Allowed whole-body IK step of the placo references (walk, dance): the IK runs duration / step
times, so a finer step costs time without changing the 50 Hz reference; a coarser one than a
50 Hz frame leaves placo's trajectory between IK steps [s]."""


@dataclass(frozen=True)
class WalkConfig:
    """Commanded velocity and G1 walk parameters for placo."""

    vx: float = 0.5  # forward velocity command [m/s]
    vy: float = 0.0  # lateral velocity command [m/s]
    wz: float = 0.0  # yaw rate command [rad/s]
    duration: float = 8.0  # approximate length of the walk, start and stop included [s]
    output_fps: float = 50.0  # reference frame rate [1/s]
    ik_dt_s: float = 0.005  # whole-body IK step [s]
    com_height_m: float = 0.66  # constant CoM height of the LIPM (bent knees) [m]
    feet_spacing_m: float = 0.24  # lateral distance between the sole centres [m]
    single_support_s: float = 0.45  # single-support duration [s]
    double_support_ratio: float = 0.2  # double-support duration / single-support duration [-]
    startend_double_support_ratio: float = 2.0  # start/stop double support / single support [-]
    foot_height_m: float = 0.08  # swing-foot apex height [m]
    zmp_margin_m: float = 0.01  # ZMP kept this far inside the sole [m]
    max_step_forward_m: float = 0.3  # footstep limit forward [m]
    max_step_backward_m: float = 0.15  # footstep limit backward [m]
    max_step_lateral_m: float = 0.15  # footstep limit sideways [m]
    max_step_yaw_rad: float = 0.5  # footstep yaw limit [rad]
    smoothing_window_s: float = 0.1  # Savitzky-Golay window for v and a [s]

    def __post_init__(self) -> None:
        """Reject NaN / inf values and sizes out of bounds, naming the field and its flag."""
        require_finite_fields(self)
        require_within(
            self, "duration", 0.0, MAX_WALK_DURATION_S, "s", low_open=True,
            why="the walk repeats one step cycle, so a longer reference adds nothing to eta0 while "
            "planning, IK and the per-frame QPs grow with it",
        )  # fmt: skip
        require_within(
            self, "ik_dt_s", *IK_DT_RANGE_S, "s",
            why="the IK runs duration / ik_dt_s steps and follows placo's trajectory between them",
        )  # fmt: skip
        require_ranges(self, {
            "vx": (-10.0, 10.0, "m/s"), "vy": (-10.0, 10.0, "m/s"), "wz": (-10.0, 10.0, "rad/s"),
            "output_fps": (1.0, 1000.0, "1/s"), "com_height_m": (0.2, 1.2, "m"),
            "feet_spacing_m": (0.0, 1.0, "m"), "single_support_s": (0.05, 10.0, "s"),
            "double_support_ratio": (0.0, 20.0, ""), "startend_double_support_ratio": (0.0, 50.0, ""),
            "foot_height_m": (0.0, 1.0, "m"), "zmp_margin_m": (0.0, 0.2, "m"),
            "max_step_forward_m": (0.0, 2.0, "m"), "max_step_backward_m": (0.0, 2.0, "m"),
            "max_step_lateral_m": (0.0, 2.0, "m"), "max_step_yaw_rad": (0.0, 3.15, "rad"),
            "smoothing_window_s": (0.0, 5.0, "s"),
        })  # fmt: skip


def placo_urdf_text(urdf_path: Path | None = None) -> str:
    """The G1 URDF with ``left_foot``, ``right_foot``, ``trunk`` frames and absolute mesh paths."""
    urdf_path = urdf_path or g1_urdf_path()
    text = urdf_path.read_text()
    offset = " ".join(f"{x:g}" for x in g1.SOLE_CENTER_OFFSET_M)
    extra = []
    for side in ("left", "right"):
        extra.append(
            f'<link name="{side}_foot"/><joint name="{side}_foot_frame" type="fixed">'
            f'<parent link="{side}_ankle_roll_link"/><child link="{side}_foot"/>'
            f'<origin xyz="{offset}" rpy="0 0 0"/></joint>'
        )
    extra.append(
        '<link name="trunk"/><joint name="trunk_frame" type="fixed"><parent link="pelvis"/>'
        '<child link="trunk"/><origin xyz="0 0 0" rpy="0 0 0"/></joint>'
    )
    text = text.replace("</robot>", "\n".join(extra) + "\n</robot>")
    description_dir = urdf_path.parent.parent
    return text.replace("package://example-robot-data/robots/g1_description", str(description_dir))


def _placo_robot():
    import placo

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "g1_placo.urdf"
        path.write_text(placo_urdf_text())
        robot = placo.HumanoidRobot(str(path), placo.Flags.ignore_collisions)
    names = list(robot.joint_names())
    if names != list(g1.JOINT_NAMES):
        raise RuntimeError(f"placo joint order {names[:3]}... differs from robots.g1.JOINTS.")
    return robot


def _parameters(cfg: WalkConfig, dt_plan_steps: int):
    import placo

    p = placo.HumanoidParameters()
    p.single_support_duration = cfg.single_support_s
    p.single_support_timesteps = 10
    p.double_support_ratio = cfg.double_support_ratio
    p.startend_double_support_ratio = cfg.startend_double_support_ratio
    p.planned_timesteps = dt_plan_steps
    p.walk_com_height = cfg.com_height_m
    p.walk_foot_height = cfg.foot_height_m
    p.walk_trunk_pitch = 0.0
    p.walk_foot_rise_ratio = 0.2
    p.foot_length = 2 * g1.SOLE_HALF_LENGTH_M
    p.foot_width = 2 * g1.SOLE_HALF_WIDTH_M
    p.feet_spacing = cfg.feet_spacing_m
    p.zmp_margin = cfg.zmp_margin_m
    p.walk_max_dx_forward = cfg.max_step_forward_m
    p.walk_max_dx_backward = cfg.max_step_backward_m
    p.walk_max_dy = cfg.max_step_lateral_m
    p.walk_max_dtheta = cfg.max_step_yaw_rad
    return p


@dataclass
class WalkPlan:
    """A planned walk: the reference plus what placo planned."""

    reference: Reference  # the 50 Hz whole-body reference
    footsteps_w: np.ndarray  # (K, 3) footstep x, y [m] and yaw [rad] in the order planned
    footstep_sides: list[str]  # (K,) "left" / "right"
    planning_time_s: float  # placo footstep + CoM planning [s]
    ik_time_s: float  # whole-body IK over the walk [s]
    max_stance_slip_m: float  # largest drift of a stance sole over one 50 Hz frame [m]


def plan_walk(cfg: WalkConfig = WalkConfig(), robot: G1Pinocchio | None = None) -> WalkPlan:
    """Plan a walk at (vx, vy, wz) with placo and return the reference and the plan.

    The start is placed so that the initial mid-feet point is at the world origin.
    """
    import time

    import placo

    robot = robot or build_pinocchio_model()
    probot = _placo_robot()
    ss = cfg.single_support_s
    step_period = ss * (1.0 + cfg.double_support_ratio)
    startend = 2 * cfg.startend_double_support_ratio * ss
    num_steps = max(2, int(round((cfg.duration - startend) / step_period)))
    plan_dt = ss / 10
    params = _parameters(cfg, int(math.ceil((cfg.duration + 4.0) / plan_dt)))

    solver = placo.KinematicsSolver(probot)
    solver.enable_velocity_limits(True)
    solver.dt = cfg.ik_dt_s
    tasks = placo.WalkTasks()
    tasks.trunk_mode = False
    tasks.initialize_tasks(solver, probot)
    legs = ("hip", "knee", "ankle")
    upper = {j.name: j.stand_rad for j in g1.JOINTS if j.name.split("_")[1] not in legs}
    joints_task = solver.add_joints_task()
    joints_task.set_joints(upper)
    joints_task.configure("upper_body", "soft", 1.0)
    start = np.eye(4)
    for joint in g1.JOINTS:
        probot.set_joint(joint.name, joint.stand_rad)
    probot.update_kinematics()
    tasks.reach_initial_pose(start, cfg.feet_spacing_m, cfg.com_height_m, 0.0)

    t0 = time.perf_counter()
    planner = placo.FootstepsPlannerRepetitive(params)
    planner.configure(cfg.vx * step_period, cfg.vy * step_period, cfg.wz * step_period, num_steps)
    t_left = placo.flatten_on_floor(probot.get_T_world_left())
    t_right = placo.flatten_on_floor(probot.get_T_world_right())
    footsteps = planner.plan(placo.HumanoidRobot_Side.left, t_left, t_right)
    supports = placo.FootstepsPlanner.make_supports(
        footsteps, 0.0, True, params.has_double_support(), True
    )
    check_step_command(cfg, footsteps, step_period)
    wpg = placo.WalkPatternGenerator(probot, params)
    trajectory = wpg.plan(supports, probot.com_world(), 0.0)
    planning_time = time.perf_counter() - t0

    t0 = time.perf_counter()
    fine_q, fine_contacts, fine_com = [], [], []
    num_fine = int(math.floor(trajectory.t_end / cfg.ik_dt_s)) + 1
    for k in range(num_fine):
        t = k * cfg.ik_dt_s
        tasks.update_tasks_from_trajectory(trajectory, t)
        probot.update_kinematics()
        solver.solve(True)
        both = trajectory.support_is_both(t)
        if not both:
            probot.update_support_side(str(trajectory.support_side(t)))
            probot.ensure_on_floor()
        fine_q.append(probot.state.q.copy())
        fine_com.append(np.array(trajectory.get_p_world_CoM(t)))
        if both:
            fine_contacts.append((True, True))
        else:
            side = str(trajectory.support_side(t))
            fine_contacts.append((side == "left", side == "right"))
    ik_time = time.perf_counter() - t0

    fine_q = np.array(fine_q)
    # Put the initial mid-feet point at the world origin (placo starts elsewhere).
    offset_xy = _mid_feet_xy(robot, fine_q[0])
    fine_q[:, :2] -= offset_xy
    com_plan_w = np.array(fine_com)
    com_plan_w[:, :2] -= offset_xy
    fine_q[:, 3:7] /= np.linalg.norm(fine_q[:, 3:7], axis=1, keepdims=True)
    v_fine, a_fine = differentiate(fine_q, cfg.ik_dt_s, cfg.smoothing_window_s, 3, robot)
    stride = int(round(1.0 / (cfg.output_fps * cfg.ik_dt_s)))
    if abs(stride * cfg.ik_dt_s * cfg.output_fps - 1.0) > 1e-9:
        raise ValueError("WalkConfig.output_fps must divide 1 / ik_dt_s (e.g. 50 Hz and 5 ms).")
    sel = slice(0, None, stride)
    q, v, a = fine_q[sel], v_fine[sel], a_fine[sel]
    contacts = np.array(fine_contacts, dtype=bool)[sel]
    phase = np.where(contacts.all(axis=1), 0, 1).astype(np.int64)
    ref = Reference(
        time_s=np.arange(q.shape[0]) / cfg.output_fps,
        q=q,
        v=v,
        a=a,
        contacts=contacts,
        phase=phase,
        phase_names=WALK_PHASES,
        dt=1.0 / cfg.output_fps,
        name="walk",
        extras={"com_plan_w": com_plan_w[sel]},
    ).validate()
    steps = np.array(
        [
            [fs.frame[0, 3], fs.frame[1, 3], math.atan2(fs.frame[1, 0], fs.frame[0, 0])]
            for fs in footsteps
        ]
    )
    steps[:, :2] -= offset_xy
    return WalkPlan(
        reference=ref,
        footsteps_w=steps,
        footstep_sides=[str(fs.side) for fs in footsteps],
        planning_time_s=planning_time,
        ik_time_s=ik_time,
        max_stance_slip_m=stance_slip_m(ref, robot),
    )


def planned_step_s(cfg: WalkConfig, footsteps) -> np.ndarray:
    """Mean step (dx [m], dy [m], dyaw [rad]) placo planned, each in the previous foot's frame.

    The first step (to the initial stance) and the last (feet together) are left out; dy is
    measured from the nominal feet spacing.
    """
    rel_steps = []
    for k in range(2, len(footsteps) - 1):
        rel = np.linalg.inv(footsteps[k - 1].frame) @ footsteps[k].frame
        spacing = cfg.feet_spacing_m if "left" in str(footsteps[k].side) else -cfg.feet_spacing_m
        rel_steps.append([rel[0, 3], rel[1, 3] - spacing, math.atan2(rel[1, 0], rel[0, 0])])
    return np.mean(rel_steps, axis=0) if rel_steps else np.zeros(3)


def check_step_command(cfg: WalkConfig, footsteps, step_period_s: float) -> None:
    """Raise :class:`ValueError` when placo clamped the commanded velocity to its step limits.

    placo's footstep planner clips each step to the ``max_step_*`` limits without a word; the walk
    would then be slower than ``(vx, vy, wz)`` while the artifact records the command. A step
    shorter than asked by more than 2 % (and 5 mm or 0.01 rad) is an error that says what the
    limits allow.
    """
    asked = np.array([cfg.vx, cfg.vy, cfg.wz]) * step_period_s
    got = planned_step_s(cfg, footsteps)
    short = np.abs(asked) - np.abs(got) > np.maximum(0.02 * np.abs(asked), [0.005, 0.005, 0.01])
    if not short.any():
        return
    rate = got / step_period_s
    raise ValueError(
        f"solve-walk: the command (--vx, --vy, --wz) = ({cfg.vx:g} m/s, {cfg.vy:g} m/s, "
        f"{cfg.wz:g} rad/s) asks for steps of ({asked[0]:.3f} m, {asked[1]:.3f} m, "
        f"{asked[2]:.3f} rad) every {step_period_s:.2f} s, but the footstep limits "
        f"(--max-step-forward-m {cfg.max_step_forward_m:g}, --max-step-backward-m "
        f"{cfg.max_step_backward_m:g}, --max-step-lateral-m {cfg.max_step_lateral_m:g}, "
        f"--max-step-yaw-rad {cfg.max_step_yaw_rad:g}) clamp them to ({got[0]:.3f} m, "
        f"{got[1]:.3f} m, {got[2]:.3f} rad): the robot would walk at ({rate[0]:.3f} m/s, "
        f"{rate[1]:.3f} m/s, {rate[2]:.3f} rad/s). Lower the command to that, or raise the limits."
    )


def _mid_feet_xy(robot: G1Pinocchio, q: np.ndarray) -> np.ndarray:
    data = robot.data()
    pin.framesForwardKinematics(robot.model, data, q)
    return 0.5 * sum(data.oMf[robot.frame_ids[n]].translation[:2] for n in g1.SOLE_FRAMES)


def stance_slip_m(ref: Reference, robot: G1Pinocchio | None = None) -> float:
    """Largest displacement [m] of a sole between consecutive frames where it is in contact."""
    robot = robot or build_pinocchio_model()
    data = robot.data()
    pos = np.empty((ref.num_frames, 2, 3))
    for t in range(ref.num_frames):
        pin.framesForwardKinematics(robot.model, data, ref.q[t])
        for s, name in enumerate(g1.SOLE_FRAMES):
            pos[t, s] = data.oMf[robot.frame_ids[name]].translation
    both = ref.contacts[1:] & ref.contacts[:-1]
    moves = np.linalg.norm(np.diff(pos, axis=0), axis=-1)
    return float(moves[both].max()) if both.any() else 0.0
