"""The assistive-wrench oracle: a contact-consistent inverse-dynamics QP per frame (proxsuite).

Given q, v, a (Pinocchio layout) and which soles touch the ground, find the least assistive pelvis
wrench ``w`` with which the G1 follows the motion::

    min   w^T W w + eps_f |f|^2 + eps_t |tau|^2
    s.t.  ID(q, v, a) = S^T tau + sum_soles J_sole^T G f_sole + J_w^T w      (35 rows, exact)
          f corner forces of a sole in contact: world-z normal >= f_min, |f_x|, |f_y| <= mu f_z
          f of a sole not in contact = 0
          |tau| <= alpha * robots.g1.EFFORT_LIMIT_NM

``ID(q, v, a) = M(q) a + h(q, v)`` (Pinocchio RNEA, plus the rotor armature of :mod:`robots.g1` on
the joint rows so the oracle matches the simulated robot). Each sole carries four corner forces (the
corners of the sole rectangle, :func:`robots.g1.sole_corners_m`), expressed in world axes. A friction
pyramid per corner makes each sole wrench unilateral, inside the (linearised) friction cone and
with its centre of pressure inside the sole rectangle, with no extra constraint. The ground is
flat with a world-vertical normal.

**The wrench frame.** ``w = [f_w (3) [N], m_w (3) [Nm]]`` is a world-frame force and a world-frame
torque about the *centre of mass of the pelvis body*. That is exactly what MuJoCo's
``data.xfrc_applied[pelvis_body_id]`` expects (world axes, applied at ``xipos``), so
:func:`xfrc_applied_from_pelvis_wrench` is the identity, kept as a named function so every consumer
makes the conversion explicit. In Pinocchio it enters through the Jacobian ``J_w`` of a point at the
pelvis CoM with LOCAL_WORLD_ALIGNED axes (:func:`pelvis_wrench_jacobian`).

**Torque limits too tight: the novice model at every frame.** ``w`` acts on the pelvis only, so
it cannot hold a limb whose joints are passive. With the hard QP (``soft_joint_rows=False``)
``alpha = 0`` (or too small an alpha) is infeasible, proxsuite says so and the frame is reported
with ``solved = False`` and a large residual. By default the 29 joint rows are *soft*: each may
miss a torque ``eps`` (``missing_torque_nm``) at a cost ``missing_torque_weight |eps|^2`` (100 per
(N m)^2 against 1 per N^2 on ``w``, so help is preferred wherever help can do the job), while the
six base rows hold exactly. Where a limb lacks torque it falls behind the reference (``eps != 0``:
the torque it would need beyond ``alpha tau_max``; its joint acceleration lags by about
``eps / M_jj``) and ``w`` says how much pelvis help keeps the base on its path; the QP is feasible
at every frame for every alpha >= 0. Where the hard QP is feasible and no torque limit binds,
``eps`` only trades against the 1e-4 torque regularisation (|eps| ~ 1e-6 |tau|), so the answer is
the hard one. (Soft joint *accelerations*, ``da`` with the column ``-M[:, joints]``, are the
same model, but the wrists' small inertia makes that QP ill-conditioned: proxsuite returned false
infeasibility certificates and took ~170 ms per backflip frame.) The *upper* envelope of help is
therefore not alpha = 0 but the no-contact wrench (both soles off, alpha = 1): the pelvis wrench that
replaces the ground altogether.

**Feasible without help.** ``w`` is unbounded, so the QP is always feasible; contacts and torque
limits are hard. A frame is *unaided* when ``|w|_2 <= unaided_tol`` (default 0.5, N and Nm mixed as
in W = identity): the regularisation and solver tolerance leave ``|w|`` of order 1e-3 on motions
the robot can do alone, and half a newton is far below anything a learner would notice.

Consecutive frames are warm-started (proxsuite ``update`` + ``solve`` with the previous primal-dual
solution); the problem size is fixed (88 variables: 2 x 12 corner forces, 6 wrench, 29 torques,
29 joint-acceleration errors).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import proxsuite

from optimal_control.reference import NV, Reference
from optimal_control.wrench_profile import WrenchProfile
from robots import g1
from robots.pinocchio_model import G1Pinocchio, build_pinocchio_model

NUM_SOLES = len(g1.SOLE_FRAMES)
CORNERS_PER_SOLE = 4
NF = NUM_SOLES * CORNERS_PER_SOLE * 3
"""Number of contact-force variables (24)."""
NW = 6
NT = g1.NUM_JOINTS
NX = NF + NW + 2 * NT
"""Number of QP variables (88): corner forces, wrench, torques, missing joint torques."""
SLICE_F = slice(0, NF)
SLICE_W = slice(NF, NF + NW)
SLICE_TAU = slice(NF + NW, NF + NW + NT)
SLICE_EPS = slice(NF + NW + NT, NX)
_INF = 1e20  # proxsuite treats |bound| >= 1e20 as infinite
_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED


@dataclass(frozen=True)
class WrenchQPConfig:
    """Options of the per-frame wrench QP."""

    alpha: float = 1.0  # fraction of robots.g1.EFFORT_LIMIT_NM the joints may use [-]
    friction_coefficient: float = 0.7  # pyramid slope |f_t| <= mu f_n per corner, per axis [-]
    min_normal_force_n: float = 0.0  # least normal force of each corner of a contact sole [N]
    force_weight: float = 1.0  # weight of |w_force|^2 in the cost [1/N^2]
    torque_weight: float = 1.0  # weight of |w_torque|^2 in the cost [1/(N m)^2]
    contact_force_reg: float = 1e-4  # eps_f, weight of |f|^2 [1/N^2]
    joint_torque_reg: float = 1e-4  # eps_t, weight of |tau|^2 [1/(N m)^2]
    unaided_tol: float = 0.5  # |w|_2 at or below which a frame needs no help [N, N m]
    include_armature: bool = True  # add rotor armature (robots.g1.ARMATURE) to the joint rows [-]
    eps_abs: float = 1e-5  # proxsuite absolute tolerance on residuals [N, N m]
    max_iter: int = 1000  # proxsuite iteration cap [-]
    warm_start: bool = True  # start each frame from the previous solution [-]
    # The novice model must answer at every frame: with soft joint rows a joint may miss torque
    # eps (cost missing_torque_weight |eps|^2) while the six base rows hold exactly, so a limb
    # that lacks torque falls behind instead of making the frame infeasible, and the wrench keeps
    # the base on its path. False: the hard QP (eps = 0; infeasible where a limb lacks torque).
    soft_joint_rows: bool = True  # joint rows soft (missing torque allowed), base rows exact [-]
    missing_torque_weight: float = 100.0  # weight of |eps|^2 [1/(N m)^2, vs 1/N^2 on w]
    lagging_tol_nm: float = 0.5  # |eps|_inf above this: a joint lacks torque, it lags [N m]


@dataclass
class FrameSolution:
    """Result of one frame of the wrench QP."""

    wrench_w: np.ndarray  # (6,) pelvis wrench [f_w N, m_w N m] at the pelvis CoM, world axes
    contact_wrench_w: np.ndarray  # (2, 6) sole wrenches [N, N m] about each sole origin, world axes
    corner_forces_w: np.ndarray  # (2, 4, 3) corner forces [N], world axes
    tau_nm: np.ndarray  # (29,) joint torques [N m]
    missing_torque_nm: np.ndarray  # (29,) eps: torque the joints lack to follow [N m]
    residual: float  # max |dynamics row residual| [N or N m]
    solved: bool  # proxsuite converged (False: e.g. alpha too small to hold the limbs at all)
    unaided: bool  # |w| <= unaided_tol and no joint lags: the robot does this frame alone
    iterations: int  # proxsuite iterations
    warm_started: bool  # answered by the warm-started solve (False: by a retry)
    status: str  # proxsuite status name
    solve_time_s: float  # model terms + QP time [s]


def _skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


def _skew_batch(r: np.ndarray) -> np.ndarray:
    out = np.zeros((r.shape[0], 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -r[:, 2], r[:, 1]
    out[:, 1, 0], out[:, 1, 2] = r[:, 2], -r[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -r[:, 1], r[:, 0]
    return out


def pelvis_com_offset_m(robot: G1Pinocchio) -> np.ndarray:
    """Centre of mass of the pelvis body in the pelvis frame [m], shape (3,)."""
    return np.asarray(robot.model.inertias[1].lever, dtype=float).copy()


def pelvis_wrench_jacobian(
    robot: G1Pinocchio, data: pin.Data, com_offset_m: np.ndarray | None = None
) -> np.ndarray:
    """Jacobian (6, 35) of the pelvis CoM point with world axes: tau_gen = J^T w.

    Needs ``pin.computeJointJacobians`` (which also runs forward kinematics) on ``data`` first. Rows
    0:3 map v to the world velocity of the pelvis CoM, rows 3:6 to the world angular velocity.
    ``com_offset_m`` (3,) caches :func:`pelvis_com_offset_m`.
    """
    jac = pin.getJointJacobian(robot.model, data, 1, pin.LOCAL_WORLD_ALIGNED)
    offset = pelvis_com_offset_m(robot) if com_offset_m is None else com_offset_m
    r_w = data.oMi[1].rotation @ offset
    out = jac.copy()
    out[:3] -= _skew(r_w) @ jac[3:]  # v_com = v_origin + omega x r = v_origin - [r]x omega
    return out


def generalized_force_of_pelvis_wrench(
    robot: G1Pinocchio, q: np.ndarray, wrench_w: np.ndarray
) -> np.ndarray:
    """Generalized force (35,) in Pinocchio's v-coordinates of a pelvis wrench (6,) [N, N m]."""
    data = robot.data()
    pin.computeJointJacobians(robot.model, data, q)
    return pelvis_wrench_jacobian(robot, data).T @ np.asarray(wrench_w, dtype=float)


def xfrc_applied_from_pelvis_wrench(wrench_w: np.ndarray) -> np.ndarray:
    """MuJoCo ``xfrc_applied`` row(s) (..., 6) of the pelvis for oracle wrench(es) (..., 6).

    The oracle's wrench is already MuJoCo's convention (world force, world torque about the body's
    CoM), so this is a copy; keep calling it so the convention stays explicit at every use.
    """
    return np.array(wrench_w, dtype=float, copy=True)


def pelvis_wrench_from_xfrc_applied(xfrc: np.ndarray) -> np.ndarray:
    """Inverse of :func:`xfrc_applied_from_pelvis_wrench`."""
    return np.array(xfrc, dtype=float, copy=True)


class WrenchQP:
    """The per-frame wrench QP with warm start. Reuse one instance along a trajectory.

    Example::

        qp = WrenchQP(WrenchQPConfig(alpha=0.5))
        sol = qp.solve(q, v, a, contacts=(True, True))
        sol.wrench_w  # (6,) pelvis wrench for MuJoCo xfrc_applied
    """

    def __init__(self, cfg: WrenchQPConfig = WrenchQPConfig(), robot: G1Pinocchio | None = None):
        if cfg.alpha < 0:
            raise ValueError(f"WrenchQPConfig.alpha must be >= 0, got {cfg.alpha}.")
        if cfg.friction_coefficient < 0:
            raise ValueError(
                f"WrenchQPConfig.friction_coefficient must be >= 0, got {cfg.friction_coefficient}."
            )
        self.cfg = cfg
        self.robot = robot or build_pinocchio_model()
        self.data = self.robot.data()
        self._sole_ids = [self.robot.frame_ids[name] for name in g1.SOLE_FRAMES]
        self._corners_m = g1.sole_corners_m()
        self._joint_v = self.robot.joint_v_index
        self._armature = g1.ARMATURE if cfg.include_armature else np.zeros(g1.NUM_JOINTS)
        self._hessian = self._build_hessian()
        self._friction_rows = self._build_friction_rows()
        self._selection_t = np.zeros((NV, NT))
        self._selection_t[self._joint_v, np.arange(NT)] = 1.0
        self._pelvis_com_m = pelvis_com_offset_m(self.robot)
        self._box_cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        # One warm-started problem per mode: hard joint rows (eps = 0) and soft (eps free).
        self._qps: dict[bool, proxsuite.proxqp.dense.QP | None] = {False: None, True: None}

    def _build_hessian(self) -> np.ndarray:
        c = self.cfg
        diag = np.concatenate(
            [
                np.full(NF, c.contact_force_reg),
                np.full(3, c.force_weight),
                np.full(3, c.torque_weight),
                np.full(NT, c.joint_torque_reg),
                np.full(NT, c.missing_torque_weight),
            ]
        )
        return 2.0 * np.diag(diag)

    def _build_friction_rows(self) -> np.ndarray:
        mu = self.cfg.friction_coefficient
        rows = []
        for corner in range(NUM_SOLES * CORNERS_PER_SOLE):
            base = 3 * corner
            for axis in (0, 1):
                for sign in (1.0, -1.0):
                    row = np.zeros(NX)
                    row[base + axis] = sign
                    row[base + 2] = -mu
                    rows.append(row)
        return np.array(rows)  # (32, NX): sign * f_t - mu f_n <= 0

    def reset(self) -> None:
        """Forget the warm start (the next solve initialises the QP afresh)."""
        self._qps = {False: None, True: None}

    def torque_bounds_nm(self, alpha: float | None = None) -> np.ndarray:
        """Joint torque bound (29,) [N m] for ``alpha`` (default: the config's)."""
        alpha = self.cfg.alpha if alpha is None else alpha
        return alpha * g1.EFFORT_LIMIT_NM

    def model_terms(
        self, q: np.ndarray, v: np.ndarray, a: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """Equality matrix A (35, 88), right side b (35,) and sole corner offsets (world, 2x(4,3))."""
        model, data = self.robot.model, self.data
        b = pin.rnea(model, data, q, v, a).copy()
        b[self._joint_v] += self._armature * a[self._joint_v]
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        eq = np.empty((NV, NX))
        offsets = []
        for s, fid in enumerate(self._sole_ids):
            jac = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            r_w = self._corners_m @ data.oMf[fid].rotation.T  # (4, 3) corner offsets, world axes
            offsets.append(r_w)
            # Force f at (sole origin + r): generalized force J_lin^T f + J_ang^T (r x f), and
            # r x f = [r]x f, so the block of corner k is J_lin^T + J_ang^T [r_k]x.
            skews = _skew_batch(r_w)  # (4, 3, 3)
            blocks = jac[:3].T[None] + np.einsum("vi,kij->kvj", jac[3:].T, skews)  # (4, 35, 3)
            col = 3 * CORNERS_PER_SOLE * s
            eq[:, col : col + 3 * CORNERS_PER_SOLE] = blocks.transpose(1, 0, 2).reshape(NV, -1)
        eq[:, SLICE_W] = pelvis_wrench_jacobian(self.robot, data, self._pelvis_com_m).T
        eq[:, SLICE_TAU] = self._selection_t
        # Missing joint torque eps: the joint rows read tau + eps + ... = ID; base rows untouched.
        eq[:, SLICE_EPS] = self._selection_t
        return eq, b, offsets

    def _box(self, contacts: np.ndarray, alpha: float, soft: bool) -> tuple[np.ndarray, np.ndarray]:
        key = (bool(contacts[0]), bool(contacts[1]), alpha, soft)
        if key not in self._box_cache:
            self._box_cache[key] = self._make_box(contacts, alpha, soft)
        return self._box_cache[key]

    def _make_box(
        self, contacts: np.ndarray, alpha: float, soft: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        lower = np.full(NX, -_INF)
        upper = np.full(NX, _INF)
        for s in range(NUM_SOLES):
            sl = slice(3 * CORNERS_PER_SOLE * s, 3 * CORNERS_PER_SOLE * (s + 1))
            if contacts[s]:
                lower[sl][2::3] = self.cfg.min_normal_force_n
            else:
                lower[sl] = 0.0
                upper[sl] = 0.0
        tau_max = self.torque_bounds_nm(alpha)
        lower[SLICE_TAU] = -tau_max
        upper[SLICE_TAU] = tau_max
        if not soft:
            lower[SLICE_EPS] = 0.0
            upper[SLICE_EPS] = 0.0
        return lower, upper

    def _cold_solve(self, eq, b, l_box, u_box, soft: bool) -> proxsuite.proxqp.dense.QP:
        n_in = self._friction_rows.shape[0]
        qp = proxsuite.proxqp.dense.QP(NX, NV, n_in, box_constraints=True)
        qp.settings.eps_abs = self.cfg.eps_abs
        qp.settings.eps_rel = 0.0
        qp.settings.max_iter = self.cfg.max_iter
        qp.settings.verbose = False
        qp.init(
            self._hessian,
            np.zeros(NX),
            eq,
            b,
            self._friction_rows,
            np.full(n_in, -_INF),
            np.zeros(n_in),
            l_box,
            u_box,
        )
        qp.solve()
        # Only now is there a previous result: warm-starting a QP that never solved segfaults.
        qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        self._qps[soft] = qp
        return qp

    def _solve_mode(self, eq, b, contacts, alpha, soft: bool, retry: bool = True):
        """Solve one frame with hard (eps = 0) or soft joint rows: (qp, answered by warm start).

        ``retry``: on failure retry from the equality-constrained guess, then from scratch.
        """
        l_box, u_box = self._box(contacts, alpha, soft)
        qp, warm = None, False
        if self._qps[soft] is not None and self.cfg.warm_start:
            qp = self._qps[soft]
            qp.update(A=eq, b=b, l_box=l_box, u_box=u_box, update_preconditioner=False)
            qp.solve()
            warm = qp.results.info.status == _SOLVED
            if not warm and not retry:
                return qp, warm
            if not warm:
                # A warm start sometimes stops on a false infeasibility certificate. Retry on the
                # same problem from the equality-constrained guess (cheap), then from scratch.
                qp.settings.initial_guess = (
                    proxsuite.proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
                )
                qp.solve()
                qp.settings.initial_guess = (
                    proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
                )
                if qp.results.info.status != _SOLVED:
                    qp = None
        if qp is None:
            qp = self._cold_solve(eq, b, l_box, u_box, soft)
        return qp, warm

    def solve(
        self,
        q: np.ndarray,
        v: np.ndarray,
        a: np.ndarray,
        contacts: tuple[bool, bool] | np.ndarray,
        alpha: float | None = None,
    ) -> FrameSolution:
        """Solve one frame. ``contacts`` is (left, right); ``alpha`` overrides the config's."""
        start = time.perf_counter()
        alpha = self.cfg.alpha if alpha is None else float(alpha)
        contacts = np.asarray(contacts, dtype=bool)
        eq, b, offsets = self.model_terms(q, v, a)
        # Hard joint rows first: where the reference is feasible the answer is exactly the
        # least-help one. Where it is not (a limb lacks torque), the soft rows answer.
        qp, warm = self._solve_mode(eq, b, contacts, alpha, soft=self.cfg.soft_joint_rows)
        x = qp.results.x
        residual = float(np.max(np.abs(eq @ x - b)))
        corner = x[SLICE_F].reshape(NUM_SOLES, CORNERS_PER_SOLE, 3)
        contact_wrench = np.zeros((NUM_SOLES, 6))
        for s in range(NUM_SOLES):
            r, f = offsets[s], corner[s]
            contact_wrench[s, :3] = f.sum(axis=0)
            contact_wrench[s, 3] = np.sum(r[:, 1] * f[:, 2] - r[:, 2] * f[:, 1])
            contact_wrench[s, 4] = np.sum(r[:, 2] * f[:, 0] - r[:, 0] * f[:, 2])
            contact_wrench[s, 5] = np.sum(r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0])
        wrench = x[SLICE_W].copy()
        status = str(qp.results.info.status).split(".")[-1]
        solved = status == "PROXQP_SOLVED"
        return FrameSolution(
            wrench_w=wrench,
            contact_wrench_w=contact_wrench,
            corner_forces_w=corner.copy(),
            tau_nm=x[SLICE_TAU].copy(),
            missing_torque_nm=x[SLICE_EPS].copy(),
            residual=residual,
            solved=solved,
            unaided=solved
            and bool(np.linalg.norm(wrench) <= self.cfg.unaided_tol)
            and bool(np.abs(x[SLICE_EPS]).max() <= self.cfg.lagging_tol_nm),
            iterations=int(qp.results.info.iter),
            warm_started=warm,
            status=status,
            solve_time_s=time.perf_counter() - start,
        )

    def solve_reference(
        self, ref: Reference, alpha: float | None = None, progress: bool = False
    ) -> WrenchProfile:
        """Solve every frame of ``ref`` in order, warm-starting each from the previous one."""
        alpha = self.cfg.alpha if alpha is None else float(alpha)
        self.reset()
        frames = range(ref.num_frames)
        if progress:
            from tqdm import tqdm

            frames = tqdm(frames, desc=f"wrench QP {ref.name} alpha={alpha:g}", unit="frame")
        sols = [self.solve(ref.q[t], ref.v[t], ref.a[t], ref.contacts[t], alpha) for t in frames]
        return WrenchProfile(
            alpha=alpha,
            wrench_w=np.array([s.wrench_w for s in sols]),
            contact_wrench_w=np.array([s.contact_wrench_w for s in sols]),
            corner_forces_w=np.array([s.corner_forces_w for s in sols]),
            tau_nm=np.array([s.tau_nm for s in sols]),
            missing_torque_nm=np.array([s.missing_torque_nm for s in sols]),
            residual=np.array([s.residual for s in sols]),
            solved=np.array([s.solved for s in sols]),
            unaided=np.array([s.unaided for s in sols]),
            iterations=np.array([s.iterations for s in sols]),
            warm_started=np.array([s.warm_started for s in sols]),
            solve_time_s=np.array([s.solve_time_s for s in sols]),
            status=[s.status for s in sols],
        )


def solve_reference(
    ref: Reference, cfg: WrenchQPConfig = WrenchQPConfig(), progress: bool = False
) -> WrenchProfile:
    """Convenience: the wrench profile of ``ref`` with a fresh :class:`WrenchQP`."""
    return WrenchQP(cfg).solve_reference(ref, progress=progress)
