"""The symmetric sagittal parameterisation of the full 3-D G1 used by the backflip TO.

A backflip is a left/right-symmetric motion in the sagittal plane. The TO therefore moves
    r = [x_w, z_w, pitch, hip_pitch, knee, ankle_pitch, shoulder_pitch, elbow]  (8,)
(base position in the x-z plane [m], base pitch about the world y axis [rad], and five pitch joints,
each driving the left and the right joint together). Every other joint is held at the stand pose,
the waist pitch included: when the TO was free to swing the torso it drove the waist (50 Nm then) to its
limit for long stretches and the MuJoCo playback collapsed at the waist.
The dynamics are not reduced: r maps to the full Pinocchio q (36,), v (35,), a (35,) and the full
3-D RNEA of :mod:`optimal_control.casadi_dynamics` gives all 35 generalised forces, so held joints
get their holding torques (bounded like the others) and any out-of-plane base force the asymmetric
mass distribution needs shows up in the pelvis wrench.

Pitch is a plain real number: the base quaternion is (0, sin(pitch/2), 0, cos(pitch/2)), so the
full -2 pi turn of the flip has no wrapping or singularity (the final quaternion is -q0, the double
cover, which never enters a constraint).

Each sole touches the ground at two points on its centre line, heel and toe (x = -/+ half length in
the sole frame); the contact force at each point is world (fx, 0, fz), the same for both feet.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import casadi as ca
import mujoco
import numpy as np

from optimal_control.casadi_dynamics import (
    SymbolicDynamics,
    build_symbolic_dynamics,
    world_force_to_joint_wrench,
)
from robots import g1
from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model

if TYPE_CHECKING:
    from optimal_control.backflip.config import BackflipConfig

MOVED_JOINTS: tuple[str, ...] = (
    "hip_pitch",
    "knee",
    "ankle_pitch",
    "shoulder_pitch",
    "elbow",
)
"""Joints the TO moves, by suffix; both sides of a left/right pair move together."""
NR = 3 + len(MOVED_JOINTS)
"""Size of the sagittal configuration r."""
NF = 4
"""Contact force variables per knot: (fx, fz) at heel and toe, shared by both feet [N]."""
R_NAMES: tuple[str, ...] = ("base_x", "base_z", "base_pitch", *MOVED_JOINTS)


@dataclass(frozen=True)
class SagittalModel:
    """The full G1 seen through r, with symbolic functions (see module docstring).

    Functions:
        full_state(r, rd, rdd) -> (q (36,), v (35,), a (35,))
        inverse_dynamics(r, rd, rdd, f (4,)) -> tau (35,)   generalised force rows: [w_b; tau_j]
        sole_points(r) -> (3, 2) world positions of the left heel and toe [m]
        sole_points_velocity(r, rd) -> (3, 2) their world velocities [m/s]
        clearance_heights(r) -> (2,) heights of the left hand and knee (same as right) [m]
        shin_heights(r) -> (8,) heights of the corners of the left shin's collision box (the
            training env's primitive of the knee link, which encloses its URDF mesh) [m]
    """

    robot: G1Pinocchio  # the G1 with rotor armature on the joint rows (a copy of the shared model)
    dyn: SymbolicDynamics
    joint_columns: tuple[tuple[int, ...], ...]  # per moved joint, indices into the 29 joints
    full_state: ca.Function
    inverse_dynamics: ca.Function
    sole_points: ca.Function
    sole_points_velocity: ca.Function
    clearance_heights: ca.Function  # r -> (left hand z, left knee z) [m]
    shin_heights: ca.Function  # r -> (8,) left shin collision box corner heights [m]
    lower_r: np.ndarray  # (NR,) position lower bounds (base entries -inf) [m, rad]
    upper_r: np.ndarray  # (NR,) position upper bounds [m, rad]
    velocity_limit: np.ndarray  # (NR,) speed bounds (base entries inf) [m/s, rad/s]
    effort_limit_nm: np.ndarray  # (29,) effort limits of all joints, from the URDF [Nm]

    def r_stand(self) -> np.ndarray:
        """Sagittal configuration of the stand pose (soles on z = 0 at x = 0 under the ankle)."""
        q = self.robot.q_stand
        r = np.zeros(NR)
        r[0], r[1] = q[0], q[2]
        for i, cols in enumerate(self.joint_columns):
            r[3 + i] = g1.STAND_JOINT_POS_RAD[cols[0]]
        return r

    def to_full(self, r: np.ndarray, rd: np.ndarray, rdd: np.ndarray):
        """Numeric full (q, v, a) of arrays (T, NR) -> (T, 36), (T, 35), (T, 35)."""
        fn = self.full_state.map(r.shape[0])
        q, v, a = fn(r.T, rd.T, rdd.T)
        return np.asarray(q).T, np.asarray(v).T, np.asarray(a).T


def _joint_columns() -> tuple[tuple[int, ...], ...]:
    names = list(g1.JOINT_NAMES)
    cols = []
    for suffix in MOVED_JOINTS:
        idx = tuple(i for i, n in enumerate(names) if n.endswith(f"{suffix}_joint"))
        if not idx:
            raise ValueError(f"No G1 joint ends with '{suffix}_joint'.")
        cols.append(idx)
    return tuple(cols)


def _rot_y(angle: ca.SX) -> ca.SX:
    c, s = ca.cos(angle), ca.sin(angle)
    return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))


def sagittal_model_for(cfg: BackflipConfig) -> SagittalModel:
    """The sagittal model a :class:`~optimal_control.backflip.config.BackflipConfig` plans with:
    the URDF's effort limits, or with ``cfg.actuator_effort_limits`` the MuJoCo actuators' force
    ranges (``robots.g1.EFFORT_LIMIT_NM``, the limits the simulator applies)."""
    model = build_sagittal_model()
    if not cfg.actuator_effort_limits:
        return model
    return dataclasses.replace(
        model, effort_limit_nm=np.asarray(g1.EFFORT_LIMIT_NM, dtype=float).copy()
    )


@lru_cache(maxsize=1)
def shin_box_corners() -> tuple[np.ndarray, ...]:
    """The 8 corners (3,) of the left shin's collision box in the knee link frame [m]: the
    primitive :func:`robots.collision_primitives.fit_link_primitives` fits around the URDF mesh
    (the knee joint's frame in Pinocchio is that link's frame)."""
    from robots.collision_primitives import fit_link_primitives
    from robots.conventions import quat_wxyz_to_matrix

    shin = next(p for p in fit_link_primitives() if p.body == "left_knee_link")
    if shin.geom_type != mujoco.mjtGeom.mjGEOM_BOX:
        raise RuntimeError(f"the left shin's primitive is not a box: {shin.geom_type}")
    rot = quat_wxyz_to_matrix(np.asarray(shin.quat, dtype=float))
    half = np.asarray(shin.size_m)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return tuple(np.asarray(shin.pos_m) + rot @ (sg * half) for sg in signs)


@lru_cache(maxsize=1)
def build_sagittal_model() -> SagittalModel:
    """Build (once per process) the sagittal view of the G1 and its CasADi functions."""
    robot = build_pinocchio_model()
    model = robot.model.copy()  # the cached model is shared: edit a copy
    # rotor armature (as simulated in MuJoCo) on the joint rows of the mass matrix
    model.armature[robot.joint_v_index] = g1.ARMATURE
    robot = dataclasses.replace(robot, model=model)
    dyn = build_symbolic_dynamics(model, robot.frame_ids)
    cols = _joint_columns()
    r = ca.SX.sym("r", NR)
    rd = ca.SX.sym("rd", NR)
    rdd = ca.SX.sym("rdd", NR)
    f = ca.SX.sym("f", NF)

    q = ca.SX(robot.q_stand)
    q[0], q[1], q[2] = r[0], 0.0, r[1]
    q[3], q[4], q[5], q[6] = 0.0, ca.sin(r[2] / 2), 0.0, ca.cos(r[2] / 2)
    v = ca.SX.zeros(model.nv)
    a = ca.SX.zeros(model.nv)
    rot = _rot_y(r[2])
    omega = ca.vertcat(0.0, rd[2], 0.0)
    v_lin_b = rot.T @ ca.vertcat(rd[0], 0.0, rd[1])
    v[0:3] = v_lin_b
    v[3:6] = omega
    # Pinocchio's free-flyer acceleration is d/dt of the body-frame twist
    a[0:3] = rot.T @ ca.vertcat(rdd[0], 0.0, rdd[1]) - ca.cross(omega, v_lin_b)
    a[3:6] = ca.vertcat(0.0, rdd[2], 0.0)
    for i, joint_cols in enumerate(cols):
        for c in joint_cols:
            q[robot.joint_q_index[c]] = r[3 + i]
            v[robot.joint_v_index[c]] = rd[3 + i]
            a[robot.joint_v_index[c]] = rdd[3 + i]
    full_state = ca.Function(
        "sagittal_full_state", [r, rd, rdd], [q, v, a], ["r", "rd", "rdd"], ["q", "v", "a"]
    )

    half = g1.SOLE_HALF_LENGTH_M
    local_points = [np.array([-half, 0.0, 0.0]), np.array([half, 0.0, 0.0])]  # heel, toe
    rots, poss = dyn.joint_placement(q)
    fext = ca.SX.zeros(6 * model.njoints)
    left_pts = []
    vel_pts = []
    for side in g1.SOLE_FRAMES:
        frame = model.frames[robot.frame_ids[side]]
        joint = frame.parentJoint
        rot_j = rots[:, 3 * joint : 3 * joint + 3]
        pos_j = poss[:, joint]
        rot_s, pos_s = dyn.frame_placement[side](q)
        lin_s, ang_s = dyn.frame_velocity[side](q, v)
        wrench = ca.SX.zeros(6)
        for k, p_local in enumerate(local_points):
            p_w = pos_s + rot_s @ p_local
            force_w = ca.vertcat(f[2 * k], 0.0, f[2 * k + 1])
            wrench = wrench + world_force_to_joint_wrench(rot_j, pos_j, p_w, force_w)
            if side == g1.SOLE_FRAMES[0]:
                left_pts.append(p_w)
                vel_pts.append(lin_s + ca.cross(ang_s, rot_s @ p_local))
        fext[6 * joint : 6 * joint + 6] = wrench
    tau = dyn.rnea(q, v, a, fext)
    inverse_dynamics = ca.Function(
        "sagittal_inverse_dynamics", [r, rd, rdd, f], [tau], ["r", "rd", "rdd", "f"], ["tau"]
    )
    sole_points = ca.Function("sole_points", [r], [ca.horzcat(*left_pts)], ["r"], ["p_w"])
    # heights of the parts that could hit the floor in a deep crouch or a tuck: hands and knees
    knee = model.getJointId("left_knee_joint")
    _, hand_w = dyn.frame_placement["left_hand"](q)
    clearance = ca.Function(
        "clearance_heights", [r], [ca.vertcat(hand_w[2], poss[2, knee])], ["r"], ["z_w"]
    )
    corners = shin_box_corners()
    rot_knee = rots[:, 3 * knee : 3 * knee + 3]
    shin_z = ca.vertcat(*[(poss[:, knee] + rot_knee @ c)[2] for c in corners])
    shin = ca.Function("shin_heights", [r], [shin_z], ["r"], ["z_w"])
    sole_vel = ca.Function(
        "sole_points_velocity", [r, rd], [ca.horzcat(*vel_pts)], ["r", "rd"], ["v_w"]
    )

    lower = np.full(NR, -np.inf)
    upper = np.full(NR, np.inf)
    vel = np.full(NR, np.inf)
    for i, joint_cols in enumerate(cols):
        lower[3 + i] = max(robot.position_lower_rad[c] for c in joint_cols)
        upper[3 + i] = min(robot.position_upper_rad[c] for c in joint_cols)
        vel[3 + i] = min(robot.velocity_limit_rad_s[c] for c in joint_cols)
    return SagittalModel(
        robot=robot,
        dyn=dyn,
        joint_columns=cols,
        full_state=full_state,
        inverse_dynamics=inverse_dynamics,
        sole_points=sole_points,
        sole_points_velocity=sole_vel,
        clearance_heights=clearance,
        shin_heights=shin,
        lower_r=lower,
        upper_r=upper,
        velocity_limit=vel,
        # the URDF's effort limits (35 Nm at the ankles and waist roll/pitch, where robots.g1's
        # actuator table has the two-motor linkage's 50 Nm): the TO plans within the URDF
        effort_limit_nm=robot.model.effortLimit[robot.joint_v_index].copy(),
    )
