"""Symbolic rigid-body dynamics in CasADi over a numeric ``pinocchio.Model``.

The ``pin`` wheels ship no ``pinocchio.casadi``, so this module walks the kinematic tree of a numeric
Pinocchio model (a free-flyer root and revolute joints about x, y or z, which is what the G1 URDF
has) and writes forward kinematics, the recursive Newton-Euler algorithm (RNEA) with external
forces, frame velocities and Jacobians as CasADi ``SX`` expressions, wrapped in named
``casadi.Function`` objects. The tests check each against Pinocchio to near machine precision.

Conventions are Pinocchio's:
    q = [p_w (3), quat_xyzw (4), joints]     v = [v_b (3), omega_b (3), joint rates]
the base twist is expressed in the base (pelvis) frame, and the free-flyer rows of the generalised
force are the wrench on the base in the base frame, about the base frame origin.

Spatial quantities are (linear, angular) pairs of 3-vectors expressed in a joint's local frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pinocchio as pin

GRAVITY_M_S2 = 9.81
"""Magnitude of gravity used by Pinocchio's default model [m/s^2]."""


def _rotation_about(axis: int, angle: ca.SX) -> ca.SX:
    """Rotation matrix (3, 3) about coordinate axis 0 (x), 1 (y) or 2 (z)."""
    c, s = ca.cos(angle), ca.sin(angle)
    if axis == 0:
        return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))
    if axis == 1:
        return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))


def quat_xyzw_to_rotation(quat: ca.SX) -> ca.SX:
    """Rotation matrix (3, 3) of a unit quaternion (4,) in x, y, z, w order (symbolic)."""
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        ca.horzcat(2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        ca.horzcat(2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


@dataclass
class _Placement:
    """A rigid transform: maps child coordinates to parent as p_parent = rot @ p_child + trans."""

    rot: ca.SX  # (3, 3)
    trans: ca.SX  # (3,)

    def compose(self, other: _Placement) -> _Placement:
        return _Placement(self.rot @ other.rot, self.trans + self.rot @ other.trans)

    def motion_to_child(self, lin: ca.SX, ang: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Express a twist given in the parent frame in the child frame."""
        ang_c = self.rot.T @ ang
        lin_c = self.rot.T @ (lin - ca.cross(self.trans, ang))
        return lin_c, ang_c

    def force_to_parent(self, lin: ca.SX, ang: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Express a wrench given in the child frame in the parent frame."""
        lin_p = self.rot @ lin
        return lin_p, self.rot @ ang + ca.cross(self.trans, lin_p)


def _const_placement(se3: pin.SE3) -> _Placement:
    return _Placement(ca.SX(se3.rotation), ca.SX(se3.translation))


@dataclass
class SymbolicDynamics:
    """Named CasADi functions of one Pinocchio model. Build with :func:`build_symbolic_dynamics`.

    Functions (inputs -> outputs, shapes for the G1: nq = 36, nv = 35, nj = 31 joints incl. universe):
        rnea(q, v, a, fext) -> tau (nv,)        fext (6 * nj,) per joint [force_lin, torque] local
        frame_placement_<name>(q) -> (rot (3,3), pos_w (3,))     for each requested frame
        frame_velocity_<name>(q, v) -> (vlin_w (3,), omega_w (3,))  world-aligned, at the frame
        frame_jacobian_<name>(q) -> J (6, nv)   world-aligned (linear; angular) at the frame origin
        com(q) -> c_w (3,)                       centre of mass, world
        mass_matrix(q) -> M (nv, nv)
        kinetic_energy(q, v) -> e_kin (1,)       [J]
    """

    model: pin.Model
    rnea: ca.Function
    com: ca.Function
    mass_matrix: ca.Function
    kinetic_energy: ca.Function
    frame_placement: dict[str, ca.Function] = field(default_factory=dict)
    frame_velocity: dict[str, ca.Function] = field(default_factory=dict)
    frame_jacobian: dict[str, ca.Function] = field(default_factory=dict)
    joint_placement: ca.Function | None = None  # q -> rot_i (3, 3 * nj), pos_i (3, nj)

    @property
    def total_mass_kg(self) -> float:
        """Total mass of the model [kg]."""
        return float(sum(inertia.mass for inertia in self.model.inertias))


class _TreeExpressions:
    """Symbolic kinematics and dynamics of one tree, as SX expressions of given q, v, a, fext."""

    def __init__(self, model: pin.Model, q: ca.SX) -> None:
        self.model = model
        self.q = q
        self.placements: list[_Placement] = [_Placement(ca.SX.eye(3), ca.SX.zeros(3))]
        self.local: list[_Placement] = [self.placements[0]]  # liMi: placement of i in parent
        for i in range(1, model.njoints):
            joint = model.joints[i]
            name = joint.shortname()
            iq = joint.idx_q
            if name == "JointModelFreeFlyer":
                motion = _Placement(quat_xyzw_to_rotation(q[iq + 3 : iq + 7]), q[iq : iq + 3])
            elif name in ("JointModelRX", "JointModelRY", "JointModelRZ"):
                axis = "XYZ".index(name[-1])
                motion = _Placement(_rotation_about(axis, q[iq]), ca.SX.zeros(3))
            else:
                raise NotImplementedError(
                    f"Joint '{model.names[i]}' is a {name}; casadi_dynamics supports the free-flyer "
                    "and revolute joints about x, y or z only."
                )
            local = _const_placement(model.jointPlacements[i]).compose(motion)
            self.local.append(local)
            self.placements.append(self.placements[model.parents[i]].compose(local))

    def motion_subspace(self, i: int, rate: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Joint twist S_i * rate in joint i's frame; rate has the joint's nv entries."""
        name = self.model.joints[i].shortname()
        if name == "JointModelFreeFlyer":
            return rate[0:3], rate[3:6]
        axis = "XYZ".index(name[-1])
        ang = ca.SX.zeros(3)
        ang[axis] = rate[0]
        return ca.SX.zeros(3), ang

    def joint_rate(self, i: int, vec: ca.SX) -> ca.SX:
        joint = self.model.joints[i]
        return vec[joint.idx_v : joint.idx_v + joint.nv]

    def velocities(self, v: ca.SX) -> list[tuple[ca.SX, ca.SX]]:
        """Body twists (lin, ang) in each joint's local frame."""
        out = [(ca.SX.zeros(3), ca.SX.zeros(3))]
        for i in range(1, self.model.njoints):
            lin_p, ang_p = out[self.model.parents[i]]
            lin, ang = self.local[i].motion_to_child(lin_p, ang_p)
            s_lin, s_ang = self.motion_subspace(i, self.joint_rate(i, v))
            out.append((lin + s_lin, ang + s_ang))
        return out

    def rnea(self, v: ca.SX, a: ca.SX, fext: ca.SX) -> ca.SX:
        """Generalised forces M(q) a + h(q, v) - sum_i J_i^T fext_i, shape (nv,)."""
        model = self.model
        nj = model.njoints
        vel = self.velocities(v)
        acc: list[tuple[ca.SX, ca.SX]] = [
            (ca.SX(np.array([0.0, 0.0, GRAVITY_M_S2])), ca.SX.zeros(3))
        ]
        forces: list[list[ca.SX]] = [[ca.SX.zeros(3), ca.SX.zeros(3)] for _ in range(nj)]
        for i in range(1, nj):
            lin_p, ang_p = acc[model.parents[i]]
            lin, ang = self.local[i].motion_to_child(lin_p, ang_p)
            s_lin, s_ang = self.motion_subspace(i, self.joint_rate(i, a))
            vj_lin, vj_ang = self.motion_subspace(i, self.joint_rate(i, v))
            v_lin, v_ang = vel[i]
            # bias v_i x (S qdot): zero for the free-flyer, whose S qdot is v_i itself
            c_lin = ca.cross(v_ang, vj_lin) + ca.cross(v_lin, vj_ang)
            c_ang = ca.cross(v_ang, vj_ang)
            a_lin, a_ang = lin + s_lin + c_lin, ang + s_ang + c_ang
            acc.append((a_lin, a_ang))
            inertia = model.inertias[i]
            mass, com = inertia.mass, ca.SX(inertia.lever)
            inertia_c = ca.SX(inertia.inertia)
            # momentum of body i and the inertial wrench I a + v x* (I v)
            h_lin = mass * (v_lin - ca.cross(com, v_ang))
            h_ang = inertia_c @ v_ang + ca.cross(com, h_lin)
            ia_lin = mass * (a_lin - ca.cross(com, a_ang))
            ia_ang = inertia_c @ a_ang + ca.cross(com, ia_lin)
            f_lin = ia_lin + ca.cross(v_ang, h_lin)
            f_ang = ia_ang + ca.cross(v_ang, h_ang) + ca.cross(v_lin, h_lin)
            forces[i] = [f_lin - fext[6 * i : 6 * i + 3], f_ang - fext[6 * i + 3 : 6 * i + 6]]
        tau = ca.SX.zeros(model.nv)
        for i in range(nj - 1, 0, -1):
            f_lin, f_ang = forces[i]
            joint = model.joints[i]
            if joint.shortname() == "JointModelFreeFlyer":
                tau[joint.idx_v : joint.idx_v + 3] = f_lin
                tau[joint.idx_v + 3 : joint.idx_v + 6] = f_ang
            else:
                axis = "XYZ".index(joint.shortname()[-1])
                tau[joint.idx_v] = f_ang[axis] + model.armature[joint.idx_v] * a[joint.idx_v]
            parent = model.parents[i]
            if parent > 0:
                p_lin, p_ang = self.local[i].force_to_parent(f_lin, f_ang)
                forces[parent][0] = forces[parent][0] + p_lin
                forces[parent][1] = forces[parent][1] + p_ang
        return tau

    def com(self) -> ca.SX:
        """Centre of mass in the world frame, shape (3,)."""
        total = 0.0
        acc = ca.SX.zeros(3)
        for i in range(1, self.model.njoints):
            inertia = self.model.inertias[i]
            place = self.placements[i]
            acc = acc + inertia.mass * (place.trans + place.rot @ ca.SX(inertia.lever))
            total += inertia.mass
        return acc / total

    def frame(self, frame_id: int) -> _Placement:
        frame = self.model.frames[frame_id]
        return self.placements[frame.parentJoint].compose(_const_placement(frame.placement))

    def frame_velocity_w(self, frame_id: int, v: ca.SX) -> tuple[ca.SX, ca.SX]:
        """World-aligned linear and angular velocity of a frame's origin."""
        frame = self.model.frames[frame_id]
        joint_place = self.placements[frame.parentJoint]
        lin, ang = self.velocities(v)[frame.parentJoint]
        offset = ca.SX(frame.placement.translation)
        return joint_place.rot @ (lin + ca.cross(ang, offset)), joint_place.rot @ ang


def build_symbolic_dynamics(
    model: pin.Model, frames: dict[str, int] | None = None
) -> SymbolicDynamics:
    """Build the named CasADi functions of ``model`` (see :class:`SymbolicDynamics`).

    Args:
        model: numeric Pinocchio model (free-flyer root + revolute joints about x, y or z).
        frames: operational frame name -> frame index for which to build placement, velocity and
            Jacobian functions (for the G1 use ``G1Pinocchio.frame_ids``).
    """
    if tuple(model.gravity.linear) != (0.0, 0.0, -GRAVITY_M_S2):
        raise ValueError(f"Model gravity {model.gravity.linear} differs from (0, 0, -9.81).")
    q = ca.SX.sym("q", model.nq)
    v = ca.SX.sym("v", model.nv)
    a = ca.SX.sym("a", model.nv)
    fext = ca.SX.sym("fext", 6 * model.njoints)
    tree = _TreeExpressions(model, q)
    tau = tree.rnea(v, a, fext)
    rnea = ca.Function("rnea", [q, v, a, fext], [tau], ["q", "v", "a", "fext"], ["tau"])
    tau_a = tree.rnea(ca.SX.zeros(model.nv), a, ca.SX.zeros(6 * model.njoints))
    gravity_only = tree.rnea(ca.SX.zeros(model.nv), ca.SX.zeros(model.nv), ca.SX.zeros(fext.shape))
    mass = ca.jacobian(tau_a - gravity_only, a)
    mass_fn = ca.Function("mass_matrix", [q], [ca.simplify(mass)], ["q"], ["M"])
    com_fn = ca.Function("com", [q], [tree.com()], ["q"], ["com_w"])
    e_kin = 0.5 * ca.dot(v, ca.substitute(mass, a, ca.SX.zeros(model.nv)) @ v)
    kinetic = ca.Function("kinetic_energy", [q, v], [e_kin], ["q", "v"], ["e_kin"])
    rots = ca.horzcat(*[p.rot for p in tree.placements])
    poss = ca.horzcat(*[p.trans for p in tree.placements])
    joint_placement = ca.Function("joint_placement", [q], [rots, poss], ["q"], ["rot", "pos_w"])
    out = SymbolicDynamics(
        model=model,
        rnea=rnea,
        com=com_fn,
        mass_matrix=mass_fn,
        kinetic_energy=kinetic,
        joint_placement=joint_placement,
    )
    for name, fid in (frames or {}).items():
        place = tree.frame(fid)
        out.frame_placement[name] = ca.Function(
            f"frame_placement_{name}", [q], [place.rot, place.trans], ["q"], ["rot", "pos_w"]
        )
        lin, ang = tree.frame_velocity_w(fid, v)
        out.frame_velocity[name] = ca.Function(
            f"frame_velocity_{name}", [q, v], [lin, ang], ["q", "v"], ["vlin_w", "omega_w"]
        )
        jac = ca.jacobian(ca.vertcat(lin, ang), v)
        out.frame_jacobian[name] = ca.Function(f"frame_jacobian_{name}", [q], [jac], ["q"], ["J_w"])
    return out


def world_force_to_joint_wrench(
    rot_joint: ca.SX, pos_joint_w: ca.SX, point_w: ca.SX, force_w: ca.SX
) -> ca.SX:
    """A world force applied at a world point, as a local wrench (6,) [force; torque] on a joint
    frame with world placement (rot_joint, pos_joint_w): the ``fext`` entry RNEA expects."""
    torque_w = ca.cross(point_w - pos_joint_w, force_w)
    return ca.vertcat(rot_joint.T @ force_w, rot_joint.T @ torque_w)
